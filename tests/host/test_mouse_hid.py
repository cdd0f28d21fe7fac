"""The HID source with a stand-in for hidapi's module: reports → stream bytes → packets, unplug, re-plug."""

from __future__ import annotations

import pytest

from sphere.daemon.sources.hid import HidSource, hid_report_bytes
from sphere.daemon.scripted_sphere import script_bytes


def reports(data: bytes, size: int = 63):
    """CP2110-style input reports: report ID = number of stream bytes that follow."""
    for i in range(0, len(data), size):
        chunk = data[i : i + size]
        yield [len(chunk)] + list(chunk) + [0] * (size - len(chunk))


class FakeHid:
    """The part of hidapi's ``hid`` module the source uses; ``plugged`` controls enumerate()."""

    def __init__(self, data: bytes):
        self.plugged = True
        self.opened = 0
        self._reports = list(reports(data))
        self.fail_after = None
        outer = self

        class Device:
            def open_path(self, path):
                outer.opened += 1

            def read(self, size, timeout_ms=0):
                if outer.fail_after is not None:
                    if outer.fail_after == 0:
                        raise OSError("read error (device unplugged)")
                    outer.fail_after -= 1
                return outer._reports.pop(0) if outer._reports else []

            def close(self):
                pass

        self.device = Device

    def enumerate(self, vid=0, pid=0):
        if not self.plugged:
            return []
        return [{"path": b"/dev/hidraw3", "vendor_id": 0x10C4, "product_id": 0xEA80,
                 "product_string": "MARG Sphere receiver"}]


def test_report_bytes():
    assert hid_report_bytes([3, 1, 2, 3, 9, 9]) == b"\x01\x02\x03"
    assert hid_report_bytes([0, 5, 5]) == b""
    assert hid_report_bytes([]) == b""


def test_hid_source_decodes_and_reconnects():
    data = script_bytes([("still", 0.2), ("tap", "single_tap")])
    fake = FakeHid(data)
    logs = []
    src = HidSource(product="sphere", reconnect_interval_s=0.0, log=logs.append, hid_module=fake)
    it = iter(src)
    got = []
    for _ in range(len(list(reports(data))) + 2):
        got += next(it)
    names = [dp.packet.NAME for dp in got]
    assert names[0] == "HELLO" and "EVENT" in names and names.count("RAW_SAMPLE") == 44
    assert src.stats.crc_errors == 0 and src.stats.frames_lost == 0
    assert src.state == "HID MARG Sphere receiver"
    # unplug: the read fails, the source looks again and finds it when it is back
    fake.fail_after = 0
    fake.plugged = False
    next(it)
    assert src.device is None and any("lost the HID receiver" in m for m in logs)
    next(it)
    fake.fail_after = None
    fake.plugged = True
    fake._reports = list(reports(script_bytes([("still", 0.05)])))
    more = []
    for _ in range(6):
        more += next(it)
    assert fake.opened == 2 and src.generation == 2
    assert more[0].packet.NAME == "HELLO"
    src.close()


def test_missing_hidapi_says_what_to_install(monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_hid(name, *a, **k):
        if name == "hid":
            raise ImportError("no hid")
        return real_import(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_hid)
    from sphere.daemon.sources.base import SourceError

    with pytest.raises(SourceError, match="pip install hidapi"):
        HidSource()
