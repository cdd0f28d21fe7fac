"""The uinput backend's event stream, checked without /dev/uinput: a stand-in device records exactly the
(type, code, value) triples and SYN_REPORTs that python-evdev's UInput would write to the kernel."""

from __future__ import annotations

import os

import pytest

evdev = pytest.importorskip("evdev", reason="python-evdev is not installed (pip install evdev)")
from evdev import ecodes as e  # noqa: E402

from sphere.daemon.app import SphereMouse  # noqa: E402
from sphere.daemon.backends import BackendUnavailable  # noqa: E402
from sphere.daemon.backends.uinput import UinputBackend, capabilities  # noqa: E402
from sphere.daemon.config import Config  # noqa: E402
from sphere.daemon.sources.replay import ReplaySource  # noqa: E402
from sphere.daemon.scripted_sphere import script_bytes  # noqa: E402

SYN = (e.EV_SYN, e.SYN_REPORT, 0)


class EventRecorder:
    """Has UInput's write()/syn() signature; keeps the stream as the kernel would receive it."""

    def __init__(self):
        self.events = []
        self.closed = False

    def write(self, etype, code, value):
        self.events.append((etype, code, value))

    def syn(self):
        self.events.append(SYN)

    def close(self):
        self.closed = True


def test_capabilities_are_a_relative_mouse():
    caps = capabilities()
    assert set(caps[e.EV_REL]) >= {e.REL_X, e.REL_Y}
    assert set(caps[e.EV_KEY]) == {e.BTN_LEFT, e.BTN_RIGHT, e.BTN_MIDDLE}


def test_move_and_click_event_stream():
    rec = EventRecorder()
    b = UinputBackend(device=rec)
    b.move(3, -2)
    b.move(0, 5)
    b.move(0, 0)  # nothing to say: no event, no SYN
    b.click("left")
    b.click("right", 2)
    assert rec.events == [
        (e.EV_REL, e.REL_X, 3), (e.EV_REL, e.REL_Y, -2), SYN,
        (e.EV_REL, e.REL_Y, 5), SYN,
        (e.EV_KEY, e.BTN_LEFT, 1), SYN, (e.EV_KEY, e.BTN_LEFT, 0), SYN,
        (e.EV_KEY, e.BTN_RIGHT, 1), SYN, (e.EV_KEY, e.BTN_RIGHT, 0), SYN,
        (e.EV_KEY, e.BTN_RIGHT, 1), SYN, (e.EV_KEY, e.BTN_RIGHT, 0), SYN,
    ]
    b.close()
    assert rec.closed


def test_daemon_replay_through_uinput(tmp_path):
    """A whole replay: the REL_X sum is the rotation times the sensitivity, the tap is one BTN_LEFT click."""
    cap = tmp_path / "c.bin"
    cap.write_bytes(script_bytes([("still", 1.0), ("turn", (0, 0, 1), -10.0, 1.0), ("still", 0.2),
                                  ("tap", "single_tap"), ("still", 0.3)]))
    rec = EventRecorder()
    cfg = Config().with_overrides({"outputs.page": {"enabled": False}, "output": {"screen_width_px": 1920}}, "test")
    SphereMouse(cfg, ReplaySource(cap, speed=0), UinputBackend(device=rec), log=lambda m: None).run()
    rel_x = sum(v for t, c, v in rec.events if (t, c) == (e.EV_REL, e.REL_X))
    rel_y = sum(v for t, c, v in rec.events if (t, c) == (e.EV_REL, e.REL_Y))
    assert rel_x == 480 and rel_y == 0  # 10° right × 1920 px / 40°
    keys = [(c, v) for t, c, v in rec.events if t == e.EV_KEY]
    assert keys == [(e.BTN_LEFT, 1), (e.BTN_LEFT, 0)]
    # every event group ends with a SYN_REPORT
    assert rec.events[-1] == SYN
    for i, ev in enumerate(rec.events[:-1]):
        if ev[0] == e.EV_KEY:
            assert rec.events[i + 1] == SYN


@pytest.mark.skipif(os.access("/dev/uinput", os.W_OK), reason="/dev/uinput is usable here")
def test_no_uinput_says_what_to_do():
    with pytest.raises(BackendUnavailable) as err:
        UinputBackend()
    text = str(err.value)
    assert "/dev/uinput" in text and "modprobe uinput" in text and "70-sphere-mouse.rules" in text


def test_auto_backend_falls_back_to_log_and_says_why(monkeypatch, capsys):
    from sphere.daemon.backends import open_backend

    monkeypatch.delenv("DISPLAY", raising=False)
    warnings = []
    b = open_backend("auto", warn=warnings.append)
    if b.NAME == "log":
        assert warnings and "uinput:" in warnings[0] and "x11: no X display" in warnings[0]
    b.close()
