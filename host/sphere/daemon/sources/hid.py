"""A receiver that delivers the sphere's serial byte stream in HID input reports (hidapi)."""

from __future__ import annotations

import logging

from sphere.daemon.sources.base import LinkLost, Source, SourceError, reconnect_interval_s
from sphere.settings import Param


def hid_report_bytes(report) -> bytes:
    """The stream bytes in one HID input report: the first byte (the report ID, CP2110-style) is the
    count of valid bytes that follow."""
    if not report:
        return b""
    n = report[0]
    return bytes(report[1 : 1 + n])


class HidSource(Source):
    """The receiver found by USB IDs (or its product string), reopened when it is unplugged."""

    NAME = "hid"
    DEVICE_PACED = True
    PARAMS = {
        "vendor_id": Param(0, doc="USB vendor ID of the receiver (0 = any device whose product string contains "
                                  "`product`)", lo=0, hi=0xFFFF),
        "product_id": Param(0, doc="USB product ID of the receiver (0 = any)", lo=0, hi=0xFFFF),
        "product": Param("sphere", doc="substring of the HID product string looked for when no IDs are set"),
    }
    DEVICE = "the HID receiver"

    def __init__(self, vendor_id: int = 0, product_id: int = 0, product: str = "sphere",
                 reconnect_interval_s: float = 1.0, log=None, hid_module=None):
        super().__init__(reconnect_interval_s=reconnect_interval_s, log=log)
        self.vendor_id, self.product_id, self.product = vendor_id, product_id, product.lower()
        if hid_module is None:
            try:
                import hid as hid_module  # optional: hidapi (the daemon extra)
            except ImportError:
                raise SourceError("the HID source needs hidapi: pip install hidapi") from None
        self.hid = hid_module
        self.device = None
        self.state = "looking for a HID receiver"
        self._warned = False

    @classmethod
    def from_settings(cls, s, log=None, cfg=None):
        return cls(s.vendor_id, s.product_id, s.product, reconnect_interval_s=reconnect_interval_s(cfg), log=log)

    def _find(self):
        for info in self.hid.enumerate(self.vendor_id, self.product_id):
            if self.vendor_id or self.product_id or self.product in (info.get("product_string") or "").lower():
                return info
        return None

    def _connect(self):
        info = self._find()
        if info is None:
            return None
        dev = self.hid.device()
        try:
            dev.open_path(info["path"])
        except (OSError, IOError) as e:
            if not self._warned:
                self._warned = True
                self.log(f"cannot open HID device {info.get('product_string')}: {e} (see the udev rule in "
                         "host/packaging/)", logging.WARNING)
            return None
        self._warned = False
        self.device = dev
        self.stream.restart()
        self.state = f"HID {info.get('product_string') or info['path']}"
        self.log(f"receiver found: {self.state}")
        return []

    def _read(self) -> bytes:
        try:
            report = self.device.read(64, 50)
        except (OSError, IOError, ValueError) as e:
            raise LinkLost(str(e)) from None
        return hid_report_bytes(report)

    def _disconnect(self) -> None:
        dev, self.device = self.device, None
        if dev is not None:
            dev.close()
