"""The serial path end to end through a pty: discovery by HELLO, GET_HELLO when no HELLO comes, an unplug
(the pty closes) and a re-plug on the same path, a protocol-version mismatch."""

from __future__ import annotations

import os
import select
import threading
import time
import tty

import pytest

from sphere.daemon.app import SphereMouse
from sphere.daemon.backends.memory import RecordingBackend
from sphere.daemon.config import Config
from sphere.daemon.sources.serial import SerialSource
from sphere.daemon.sources.base import SourceError
from sphere.daemon.scripted_sphere import ScriptedSphere, hello_packet
from sphere.protocol import FrameDecoder, encode_frame


class FakeSphere:
    """A sphere behind a pty, reached through the symlink ``link`` (like udev's /dev/sphere).

    Like a Bluetooth module it sends nothing until the host asks with GET_HELLO; then a HELLO and the
    frames of ``script``. ``unplug()`` closes the pty."""

    def __init__(self, link, script, protocol_version=1, answer=True):
        self.link = str(link)
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.slave_name = os.ttyname(slave)
        os.close(slave)
        if os.path.lexists(self.link):
            os.unlink(self.link)
        os.symlink(self.slave_name, self.link)
        self.script = script
        self.protocol_version = protocol_version
        self.answer = answer
        self.get_hellos = 0
        self.received = 0  # bytes the host wrote to this device
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        decoder = FrameDecoder("host")
        while not self._stop.is_set():
            try:
                r, _, _ = select.select([self.master], [], [], 0.05)
                if not r:
                    continue
                data = os.read(self.master, 256)
            except OSError:
                time.sleep(0.02)  # nobody has the slave open yet
                continue
            self.received += len(data)
            for p in decoder.feed(data):
                if self.on_command(p):
                    return

    def on_command(self, p) -> bool:
        """A command from the host; True ends the device's loop."""
        if p.NAME == "GET_HELLO" and self.answer:
            self.get_hellos += 1
            self._stream()
            return True
        return False

    def _stream(self):
        sphere = ScriptedSphere()
        hello = hello_packet()
        hello.protocol_version = self.protocol_version
        frames = [sphere.frame(hello)] + [f for _, f in sphere.steps(self.script)]
        data = b"".join(frames)
        try:
            for i in range(0, len(data), 512):
                if self._stop.is_set():
                    return
                os.write(self.master, data[i : i + 512])
                time.sleep(0.002)
        except OSError:
            pass

    def unplug(self):
        self._stop.set()
        self.thread.join(2)
        os.close(self.master)
        os.unlink(self.link)


def start_daemon(source, backend=None):
    cfg = Config().with_overrides({"outputs.page": {"enabled": False}, "gyro": {"still_time_s": 0.3}}, "test")
    backend = backend or RecordingBackend()
    daemon = SphereMouse(cfg, source, backend, log=lambda m: None)
    t = threading.Thread(target=daemon.run, daemon=True)
    t.start()
    return daemon, backend, t


def wait_for(cond, timeout=20.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.02)
    return cond()


def fast_serial(port, **kw):
    args = dict(hello_timeout_s=0.15, discovery_timeout_s=1.0, link_timeout_s=1.0, reconnect_interval_s=0.1)
    args.update(kw)
    return SerialSource(port, **args)


# 10 °/s to the left for 0.5 s at 1920 px per 40°: 240 px
LEFT = [("still", 0.4), ("turn", (0, 0, 1), 10.0, 0.5), ("still", 0.2)]
RIGHT = [("still", 0.4), ("turn", (0, 0, 1), -10.0, 0.5), ("still", 0.2)]


def test_unplug_and_replug_without_restart(tmp_path):
    link = tmp_path / "sphere"
    logs = []
    dev = FakeSphere(link, LEFT)
    source = fast_serial(str(link), log=logs.append, link_timeout_s=30.0)  # only the unplug may end the link
    daemon, backend, thread = start_daemon(source)
    try:
        assert wait_for(lambda: backend.x <= -238), (backend.x, logs)
        assert abs(backend.x + 240) <= 2 and backend.y == 0
        assert dev.get_hellos >= 1  # nothing came by itself: the host asked
        dev.unplug()
        assert wait_for(lambda: source.losses == 1), logs
        assert source.serial is None
        time.sleep(0.3)  # unplugged for a while: the daemon keeps looking, does not end
        assert thread.is_alive()
        dev = FakeSphere(link, RIGHT)  # plugged in again: a new pty behind the same path
        assert wait_for(lambda: source.connects == 2), logs
        assert wait_for(lambda: backend.x >= -2), (backend.x, logs)
        assert abs(backend.x) <= 4
        assert any("reconnected" in m for m in logs) and any("lost the sphere" in m for m in logs)
    finally:
        daemon.stop()
        thread.join(5)
        dev._stop.set()
    assert not thread.is_alive()


def test_discovery_asks_only_the_port_named_and_never_writes_to_others(tmp_path):
    """A glob match is only listened to; the literal path (the udev symlink /dev/sphere) may be asked with GET_HELLO."""
    silent = FakeSphere(tmp_path / "ttyFAKE0", LEFT, answer=False)  # some other serial device
    sphere = FakeSphere(tmp_path / "sphere", LEFT)
    source = fast_serial("auto", candidates=[str(tmp_path / "ttyFAKE*"), str(tmp_path / "sphere")],
                         discovery_timeout_s=0.5, usb_ids=[])
    daemon, backend, thread = start_daemon(source)
    try:
        assert wait_for(lambda: source.port_name is not None)
        assert source.port_name == str(tmp_path / "sphere")
        assert wait_for(lambda: backend.x <= -238)
        assert silent.received == 0  # the unidentified device got nothing
    finally:
        daemon.stop()
        thread.join(5)
        silent.unplug()
        sphere.unplug()


def test_protocol_version_mismatch_stops_with_what_to_update(tmp_path):
    dev = FakeSphere(tmp_path / "sphere", LEFT, protocol_version=9)
    source = fast_serial(str(tmp_path / "sphere"))
    with pytest.raises(SourceError, match="protocol version 9.*update the host software"):
        for _ in source:
            pass
    dev.unplug()


def test_link_timeout_counts_as_lost(tmp_path):
    """A Bluetooth link that drops delivers no error, only silence: after link_timeout_s it is reopened."""
    link = tmp_path / "rfcomm0"
    dev = FakeSphere(link, [("still", 0.2)])
    source = fast_serial(str(link), link_timeout_s=0.4)
    daemon, backend, thread = start_daemon(source)
    try:
        assert wait_for(lambda: source.connects == 1)
        assert wait_for(lambda: source.losses >= 1, timeout=5)
    finally:
        daemon.stop()
        thread.join(5)
        dev.unplug()


def test_frame_bytes_in_any_chunking_and_junk_before_hello(tmp_path):
    """Bootloader noise after a DTR reset precedes the HELLO; the source still finds it."""
    master, slave = os.openpty()
    tty.setraw(slave)
    name = os.ttyname(slave)
    os.close(slave)
    source = fast_serial(name, hello_timeout_s=5.0)

    def board():
        time.sleep(0.2)
        sphere = ScriptedSphere()
        os.write(master, b"\xff\x30\x20\x14\x10 bootloader junk \x00")
        os.write(master, encode_frame(hello_packet(), 0))
        for _, f in sphere.steps([("still", 0.1)]):
            os.write(master, f)

    t = threading.Thread(target=board, daemon=True)
    t.start()
    it = iter(source)
    got = []
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and len(got) < 10:
        got += next(it)
    source.close()
    t.join(5)
    os.close(master)
    assert got[0].packet.NAME == "HELLO"
    assert source.connects == 1


def test_serial_source_asks_the_port_for_low_latency(tmp_path):
    """sphere-mouse asks every port it opens for low latency (an FTDI's latency timer 16 → 1 ms); on a pty the
    request is CMSPAR in the termios, which the device end (the virtual board) reads on its master;
    ``[source] low_latency = false`` leaves the driver's default."""
    import termios

    from sphere.link.port import CMSPAR

    for asked in (True, False):
        master, slave = os.openpty()
        path = os.ttyname(slave)
        os.close(slave)
        src = fast_serial(path, low_latency=asked)
        ser = src._open(path)
        try:
            assert bool(termios.tcgetattr(master)[2] & CMSPAR) is asked
            assert ser.low_latency_problem is None
        finally:
            ser.close()
            os.close(master)


def test_a_driver_without_low_latency_is_said_once_at_debug(caplog):
    """A driver that refuses the request (a CH340's ch341, Bluetooth rfcomm) costs latency, not function: one
    DEBUG line (shown by ``sphere-mouse -v``), once per port, and the port is used."""
    import logging

    from sphere.link import port as serial_link

    class Refusing:
        port = "/dev/ttyUSB7"

        def set_low_latency_mode(self, on):
            raise ValueError("Failed to update ASYNC_LOW_LATENCY flag to True: [Errno 25] Inappropriate ioctl")

    problem = serial_link.request_low_latency(Refusing())
    assert problem.startswith("/dev/ttyUSB7: the driver offers no low-latency mode") and "latency_timer" in problem
    src = fast_serial("/dev/ttyUSB7")  # no log callable: the "sphere.daemon.source" logger
    caplog.set_level(logging.DEBUG, logger="sphere.daemon.source")
    opened = []

    def fake_open_port(path, *a, **kw):
        assert kw["low_latency"] is True
        ser = Refusing()
        ser.low_latency_problem = problem
        opened.append(ser)
        ser.reset_input_buffer = lambda: None
        return ser

    import sphere.daemon.sources.serial as serial_mod

    real = serial_mod.open_port
    serial_mod.open_port = fake_open_port
    try:
        src._open("/dev/ttyUSB7")
        src._open("/dev/ttyUSB7")
    finally:
        serial_mod.open_port = real
    lines = [r for r in caplog.records if "low-latency" in r.getMessage()]
    assert len(opened) == 2 and len(lines) == 1 and lines[0].levelno == logging.DEBUG


class UnpluggedDuringTheSwitch(FakeSphere):
    """A version-3 sphere that answers GET_HELLO and is pulled out the moment SET_BAUD arrives (the host is in its
    baud switch, spec §5.4)."""

    def on_command(self, p) -> bool:
        if p.NAME == "GET_HELLO":
            self.get_hellos += 1
            hello = hello_packet()
            hello.protocol_version = 3
            os.write(self.master, ScriptedSphere().frame(hello))
        elif p.NAME == "SET_BAUD":
            os.close(self.master)  # unplugged: the host's next read finds the port gone
            self.master = None
            return True
        return False

    def unplug(self):
        self._stop.set()
        self.thread.join(2)
        if self.master is not None:
            os.close(self.master)
        os.unlink(self.link)


def test_a_sphere_unplugged_during_the_baud_switch_is_looked_for_again(tmp_path):
    """Pulled out while the host moves it to 1 Mbaud: the daemon says it lost the sphere and looks for it again, as
    for any unplug (it ended with a LinkLost traceback from the switch's read)."""
    link = tmp_path / "sphere"
    logs = []
    dev = UnpluggedDuringTheSwitch(link, [])
    source = fast_serial(str(link), log=logs.append, link_timeout_s=30.0, baud_switch=1000000)
    daemon, backend, thread = start_daemon(source)
    try:
        assert wait_for(lambda: source.losses == 1), logs
        assert thread.is_alive(), logs
        assert any("lost the sphere" in m for m in logs), logs
        assert source.serial is None
        os.unlink(link)
        dev = FakeSphere(link, LEFT)  # plugged in again (a version-1 sphere: no switch)
        assert wait_for(lambda: backend.x <= -238), (backend.x, logs)
        assert source.connects == 1 and any("sphere found" in m for m in logs)
    finally:
        daemon.stop()
        thread.join(5)
        dev._stop.set()
    assert not thread.is_alive()


class PadRecorder:
    """Stands for python-evdev's UInput (no /dev/uinput here): keeps what the gamepad output writes."""

    def __init__(self, caps, **kw):
        self.device = None
        self.events: list[tuple[str, int]] = []

    def write(self, etype, code, value):
        self.events.append((code, value))

    def syn(self):
        self.events.append(("SYN", 0))

    def close(self):
        pass


def test_a_lost_link_centres_the_gamepads_sticks(tmp_path, monkeypatch):
    """The sphere rolled 10° (a third of a full stick) and then unplugged: the virtual gamepad's sticks go back to
    the centre at once (they stayed deflected, and a game kept steering with no sphere there)."""
    evdev = pytest.importorskip("evdev", reason="python-evdev is not installed (pip install evdev)")
    from evdev import ecodes

    from sphere.daemon.outputs.fanout import attach

    monkeypatch.setattr(evdev, "UInput", PadRecorder)
    link = tmp_path / "sphere"
    dev = FakeSphere(link, [("still", 0.4), ("turn", (1, 0, 0), 20.0, 0.5), ("still", 0.6)])
    source = fast_serial(str(link), link_timeout_s=30.0)  # only the unplug may end the link
    cfg = Config().with_overrides({"outputs.page": {"enabled": False}, "gyro": {"still_time_s": 0.3},
                                   "outputs.gamepad": {"enabled": True, "full_tilt_deg": 30.0}}, "test")
    outputs = attach(cfg)
    pad = outputs.outputs[0].ui
    daemon = SphereMouse(cfg, source, RecordingBackend(), stream=outputs, log=lambda m: None)
    thread = threading.Thread(target=daemon.run, daemon=True)
    thread.start()
    try:
        def stick_x():
            xs = [v for code, v in pad.events if code == ecodes.ABS_X]
            return xs[-1] if xs else 0

        assert wait_for(lambda: stick_x() > 0.3 * 32767 and not dev.thread.is_alive()), pad.events[-6:]
        held = len(pad.events)
        dev.unplug()
        assert wait_for(lambda: source.losses == 1)
        assert wait_for(lambda: stick_x() == 0, timeout=5.0), pad.events[held:]
        assert pad.events[-1] == ("SYN", 0)
    finally:
        daemon.stop()
        thread.join(5)
        outputs.stop()
