"""Outputs for other programs, each checked by a real receiver: a UDP socket decoding OpenTrack's six
doubles, python-osc's own server, an evdev reader on the uinput gamepad (where /dev/uinput is writable)."""

import math
import os
import socket
import struct
import threading
import time

import numpy as np
import pytest

from sphere import quaternion as quat
from sphere.daemon.config import Config, ConfigError, parse_set
from sphere.daemon.outputs.fanout import Outputs, attach, open_outputs
from sphere.daemon.outputs.base import relative_euler_deg
from sphere.daemon.outputs.gamepad import STICK_MAX, stick_values

X, Y, Z = np.eye(3)
START = quat.from_axis_angle(Z, math.radians(70.0))  # any heading: everything is relative to the start pose


def turned(axis, deg, base=START):
    return tuple(quat.multiply(base, quat.from_axis_angle(axis, math.radians(deg))))


def cfg_with(*items):
    """The defaults with ``items`` (--set syntax); the 3-D page off unless named (it would take port 8765)."""
    return Config().with_overrides(parse_set(["outputs.page.enabled=false", *items]), "test")


def udp_receiver():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(2.0)
    return s, s.getsockname()[1]


@pytest.mark.parametrize("axis, deg, expected", [
    (Z, 30.0, (30.0, 0.0, 0.0)),    # turned left
    (Y, -20.0, (0.0, 20.0, 0.0)),   # nose (x) up: a negative turn about y (left)
    (X, 10.0, (0.0, 0.0, 10.0)),    # rolled right: right side down
])
def test_relative_angles(axis, deg, expected):
    assert np.allclose(relative_euler_deg(tuple(START), turned(axis, deg)), expected, atol=1e-9)


def test_opentrack_datagrams_through_the_daemons_seam():
    rx, port = udp_receiver()
    cfg = cfg_with("outputs.opentrack.enabled=true", f"outputs.opentrack.port={port}", "outputs.opentrack.rate_hz=1000")
    out = attach(cfg)
    assert isinstance(out, Outputs) and [o.NAME for o in out.outputs] == ["opentrack"]
    try:
        out.position = [1.0, 2.0, 0.5]  # NWU metres from a pose source
        out.publish_orientation(tuple(START), 0)  # the reference pose
        first = struct.unpack("<6d", rx.recv(100))
        time.sleep(0.002)
        # 12° left and 8° nose up; moved 10 cm to the sphere's right (its -y at the start heading) and 5 cm up
        q = quat.multiply(turned(Z, 12.0), quat.from_axis_angle(Y, math.radians(-8.0)))
        right = quat.rotate(START, -Y)
        out.position = list(np.array([1.0, 2.0, 0.5]) + 0.10 * right + [0, 0, 0.05])
        out.publish_orientation(tuple(q), 5000)
        data = rx.recv(100)
    finally:
        out.stop()
        rx.close()
    assert len(data) == 48  # six little-endian doubles
    assert np.allclose(first, 0.0, atol=1e-9)
    x, y, z, yaw, pitch, roll = struct.unpack("<6d", data)
    assert np.allclose((x, y, z), (10.0, 5.0, 0.0), atol=1e-6)
    assert np.allclose((yaw, pitch, roll), (12.0, 8.0, 0.0), atol=1e-6)


def test_osc_messages_to_a_python_osc_server():
    from pythonosc.dispatcher import Dispatcher
    from pythonosc.osc_server import ThreadingOSCUDPServer

    got = []
    d = Dispatcher()
    d.set_default_handler(lambda address, *args: got.append((address, args)))
    server = ThreadingOSCUDPServer(("127.0.0.1", 0), d)
    port = server.server_address[1]
    t = threading.Thread(target=server.serve_forever, daemon=True)
    t.start()
    cfg = cfg_with("outputs.osc.enabled=true", f"outputs.osc.port={port}", 'outputs.osc.prefix="/ball"',
                   "outputs.osc.rate_hz=1000")
    out = attach(cfg)
    try:
        out.publish_orientation(tuple(START), 0)
        time.sleep(0.002)
        out.publish_orientation(turned(X, 25.0), 1000)
        out.publish_event("double_tap", 2000)
        out.publish_mode("3d")
        deadline = time.monotonic() + 3
        while time.monotonic() < deadline and not any(a == "/ball/mode" for a, _ in got):
            time.sleep(0.01)
    finally:
        out.stop()
        server.shutdown()
        server.server_close()
    by = {}
    for address, args in got:
        by.setdefault(address, []).append(args)
    assert np.allclose(by["/ball/quat"][-1], turned(X, 25.0), atol=1e-6)
    assert np.allclose(by["/ball/euler"][-1], (0.0, 0.0, 25.0), atol=1e-4)
    assert by["/ball/event"] == [("double_tap",)] and by["/ball/mode"] == [("3d",)]


def test_stick_values():
    v = stick_values((-15.0, 30.0, 60.0), 30.0)  # turned 15° right, nose up 30°, rolled right 60° (clipped)
    assert v == {"ABS_X": STICK_MAX, "ABS_Y": STICK_MAX, "ABS_RX": STICK_MAX // 2 + 1}


def _uinput_writable():
    return os.path.exists("/dev/uinput") and os.access("/dev/uinput", os.W_OK)


@pytest.mark.skipif(not _uinput_writable(), reason="[optional] no writable /dev/uinput here (modprobe uinput; "
                    "host/packaging/70-sphere-mouse.rules)")
def test_gamepad_read_back_with_evdev():
    import evdev
    from evdev import ecodes

    out = attach(cfg_with("outputs.gamepad.enabled=true", "outputs.gamepad.full_tilt_deg=20",
                                "outputs.gamepad.rate_hz=1000"))
    pad = out.outputs[0]
    try:
        dev = evdev.InputDevice(pad.ui.device.path)
        time.sleep(0.2)
        out.publish_orientation(tuple(START), 0)
        time.sleep(0.002)
        out.publish_orientation(turned(X, 10.0), 1000)  # rolled right half a full tilt
        out.publish_event("single_tap", 2000)
        events, deadline = [], time.monotonic() + 2
        while time.monotonic() < deadline and not any(e.type == ecodes.EV_KEY and e.value == 0 for e in events):
            e = dev.read_one()
            if e is None:
                time.sleep(0.005)
            else:
                events.append(e)
        dev.close()
    finally:
        out.stop()
    assert any(e.type == ecodes.EV_ABS and e.code == ecodes.ABS_X and e.value == round(STICK_MAX / 2) for e in events)
    keys = [(e.code, e.value) for e in events if e.type == ecodes.EV_KEY]
    assert keys == [(ecodes.BTN_SOUTH, 1), (ecodes.BTN_SOUTH, 0)]


def test_outputs_are_off_by_default_and_settings_are_checked():
    off = cfg_with()  # the 3-D page (the one output on by default) off
    assert open_outputs(off) == [] and attach(off) is None
    assert Config()["outputs.page"].enabled and not Config()["outputs.osc"].enabled
    with pytest.raises(ConfigError, match="port"):
        cfg_with("outputs.opentrack.port=70000")
    with pytest.raises(ConfigError, match="OSC address"):
        cfg_with('outputs.osc.prefix="sphere/"')


def test_an_output_that_fails_is_dropped_not_fatal():
    class Broken:
        NAME = "broken"

        def orientation(self, *a):
            raise OSError("gone")

        def close(self):
            pass

    logged = []
    out = Outputs([Broken()], log=logged.append)
    out.publish_orientation(tuple(START), 0)
    out.publish_orientation(tuple(START), 1)
    assert out.outputs == [] and logged == ["output broken stopped: gone"]
