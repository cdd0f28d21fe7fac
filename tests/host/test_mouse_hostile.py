"""sphere-mouse on a real desk (issue 14): a hostile web page, a connection flood, a frame received twice,
a gyroscope that stops answering, signals while the pointer moves, a port held by another program."""

from __future__ import annotations

import os
import socket
import threading
import time
import tty

import pytest

from sphere.daemon.app import SphereMouse
from sphere.daemon.backends.memory import RecordingBackend
from sphere.daemon.config import Config
from sphere.daemon.scripted_sphere import ScriptedSphere, hello_packet
from sphere.protocol import PacketStream, RawSample, encode_frame


def make_daemon(**overrides):
    cfg = Config().with_overrides({"outputs.page": {"enabled": False}, **overrides}, "test")
    backend = RecordingBackend()
    return SphereMouse(cfg, source=None, backend=backend, log=lambda m: None), backend


def feed_bytes(daemon, data: bytes, stream: PacketStream | None = None) -> PacketStream:
    stream = stream or PacketStream()
    for dp in stream.feed(data):
        daemon.handle(dp)
    return stream


# ---- a frame received twice: one action ----


def test_a_frame_received_twice_is_acted_on_once():
    d, b = make_daemon(events={"single_tap": "left_click"})
    sphere = ScriptedSphere()
    data = sphere.frame(hello_packet()) + b"".join(f for _, f in sphere.steps([("still", 0.3)]))
    stream = feed_bytes(d, data)
    tap = b"".join(f for _, f in sphere.steps([("tap", "single_tap")]))
    event = [f for f in tap.split(b"\x00") if f][-1] + b"\x00"  # the EVENT frame, the last of the tap
    feed_bytes(d, tap + event, stream)  # a link that re-sent the intact EVENT frame
    assert [c[0] for c in b.clicks] == ["left"]
    s = stream.stats
    assert s.duplicates == 1 and s.seq_gaps == 0 and s.frames_lost == 0  # not "255 lost"


def test_duplicate_window_keeps_real_frames():
    """Frames that only share a seq (256 frames apart) are not duplicates: their CRC differs."""
    sphere = ScriptedSphere()
    data = b"".join(f for _, f in sphere.steps([("still", 2.0)]))  # > 256 frames
    stream = PacketStream()
    out = stream.feed(data)
    assert stream.stats.duplicates == 0 and len(out) == stream.stats.frames_ok


# ---- RAW_SAMPLE flags: no gyro, no motion ----


def _raw(t_us, gyro, flags):
    return RawSample(t_us, flags, (0, 0, 256), gyro, (200, 0, -400))


def test_gyro_missing_while_still_does_not_move_the_pointer():
    """A 5 °/s offset learnt as bias, then the gyro stops answering (flags gyro_ok = 0, values 0) for 3 s while
    the sphere lies still: the pointer moves < 5 px (it ran at ~211 px/s before)."""
    logs = []
    cfg = Config().with_overrides({"outputs.page": {"enabled": False}, "orientation": {"source": "device"}}, "t")
    b = RecordingBackend()
    d = SphereMouse(cfg, source=None, backend=b, log=logs.append)
    offset = round(5.0 * 14.375)  # 5 °/s in ITG-3200 LSB about z
    stream = PacketStream()
    seq = 0
    t = 1_000_000
    frames = [encode_frame(hello_packet(), 0)]
    for _ in range(600):  # 3 s still with the offset: learnt as bias
        seq += 1
        t += 5000
        frames.append(encode_frame(_raw(t, (0, 0, offset), 0x0F), seq & 0xFF))
    feed_bytes(d, b"".join(frames), stream)
    x0, y0 = b.x, b.y
    frames = []
    for _ in range(600):  # 3 s without the gyro
        seq += 1
        t += 5000
        frames.append(encode_frame(_raw(t, (0, 0, 0), 0x0D), seq & 0xFF))
    feed_bytes(d, b"".join(frames), stream)
    assert abs(b.x - x0) + abs(b.y - y0) < 5
    assert d.sensors_missing == ("gyroscope",)
    assert any("gyroscope not answering" in m for m in logs), logs


def test_stale_gyro_does_not_move_the_pointer():
    d, b = make_daemon(orientation={"source": "device"})
    frames = [encode_frame(hello_packet(), 0)]
    for i in range(1, 400):  # a turn of 20 °/s held from the last good read (gyro_stale, protocol v2)
        frames.append(encode_frame(_raw(1_000_000 + 5000 * i, (0, 0, 288), 0x4F), i & 0xFF))
    feed_bytes(d, b"".join(frames))
    assert b.x == 0 and b.y == 0


# ---- signals only set flags ----


def test_requests_from_signal_handlers_are_served_by_the_loop():
    calls = []

    class Backend(RecordingBackend):
        def move_to(self, x, y):
            calls.append(threading.current_thread().name)

        def screen_size(self):
            return (1920, 1080)

    sphere = ScriptedSphere()
    data = sphere.frame(hello_packet()) + b"".join(f for _, f in sphere.steps([("still", 0.5)]))
    stream = PacketStream()
    batches = [[dp] for dp in stream.feed(data)]

    class Source:
        stats, state, generation, _stop = stream.stats, "test", 1, False

        def __iter__(self):
            for i, batch in enumerate(batches):
                if i == 10:
                    d.request("recentre")  # what the SIGUSR1 handler does: no backend call here
                    assert calls == []
                    d.request("pause")
                yield batch

    cfg = Config().with_overrides({"outputs.page": {"enabled": False}}, "t")
    d = SphereMouse(cfg, Source(), Backend(), log=lambda m: None)
    d.run()
    assert len(calls) == 1 and d.paused


# ---- the 3-D server: Origin, Host, connection limit ----


websockets = pytest.importorskip("websockets", reason="[optional] the 3-D stream needs websockets")


@pytest.fixture
def server():
    from sphere.daemon.stream3d import OrientationStream

    logs = []
    s = OrientationStream("127.0.0.1", 0, rate_hz=100, log=logs.append, max_clients=8)
    s.start()
    s.logs = logs
    yield s
    s.stop()


def _http(port, headers: dict, path="/ws") -> int:
    """Status code of a WebSocket upgrade request with these headers."""
    req = (f"GET {path} HTTP/1.1\r\n" + "".join(f"{k}: {v}\r\n" for k, v in headers.items())
           + "Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
           "Sec-WebSocket-Version: 13\r\n\r\n")
    with socket.create_connection(("127.0.0.1", port), timeout=5) as c:
        c.sendall(req.encode())
        return int(c.recv(200).split()[1])


def test_foreign_origin_and_host_are_refused(server):
    p = server.port
    assert _http(p, {"Host": f"127.0.0.1:{p}", "Origin": "https://evil.example"}) == 403
    assert _http(p, {"Host": f"evil.example:{p}"}) == 403  # DNS rebinding: a foreign name for 127.0.0.1
    assert _http(p, {"Host": f"localhost:{p}", "Origin": f"http://localhost:{p}"}) == 101  # the page served here
    assert _http(p, {"Host": f"127.0.0.1:{p}"}) == 101  # a local program (no Origin)
    assert _http(p, {"Host": f"evil.example:{p}"}, path="/") == 403


def _flood(port, attempts=2000, hold=200) -> list:
    """``attempts`` TCP connections to the server, the first ``hold`` kept open (returned), the rest closed."""
    held = []
    for _ in range(attempts):
        try:
            c = socket.create_connection(("127.0.0.1", port), timeout=2)
        except OSError:
            continue
        if len(held) < hold:
            held.append(c)
        else:
            c.close()
    return held


@pytest.mark.slow
def test_connection_flood_is_refused_and_the_server_keeps_serving(server):
    """2,000 connection attempts, many held open: beyond max_clients they are refused at once; afterwards a
    client still connects, and the log has a few lines, not a traceback per connection."""
    for c in _flood(server.port):
        c.close()
    time.sleep(0.3)
    print(f"\n2000 connection attempts (200 held): {server.refused} refused, log lines {len(server.logs)}")
    assert server.refused >= 1000
    assert _http(server.port, {"Host": f"127.0.0.1:{server.port}"}) == 101
    assert len(server.logs) <= 5 and not any("Traceback" in m for m in server.logs), server.logs


# ---- ports held by another program ----


def _pty():
    master, slave = os.openpty()
    tty.setraw(slave)
    name = os.ttyname(slave)
    return master, slave, name


def test_open_port_is_exclusive_and_leaves_held_ports_alone(tmp_path):
    pytest.importorskip("serial")
    import subprocess
    import sys

    from sphere.link.port import PortBusy, open_port

    master, slave, name = _pty()
    os.close(slave)
    first = open_port(name)
    try:
        with pytest.raises(PortBusy):
            open_port(name)  # sphere capture beside sphere-mouse: refused, not a split stream
    finally:
        first.close()
    # another program holds it (a 3-D printer's host program)
    holder = subprocess.Popen([sys.executable, "-c", f"import time; f = open({name!r}, 'rb', buffering=0); "
                               "print('held', flush=True); time.sleep(30)"], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(PortBusy, match="open in another program"):
            open_port(name)
    finally:
        holder.kill()
        holder.wait()
        os.close(master)


# ---- honest status counters ----


def _status_text(stream):
    from sphere.daemon.status import StatusLine

    class Src:
        state = "/dev/ttyUSB0"
        stats = stream.stats
        losses = 0

    d, _ = make_daemon()
    d.source = Src()
    clock = [0.0]
    import io

    line = StatusLine(io.StringIO(), 1.0, overwrite=False, clock=lambda: clock[0])
    line.tick(d)
    clock[0] = 1.0
    return line.tick(d)


def test_replugs_count_no_errors_and_no_lost_frames():
    """Six clean replugs of a sphere that kept running (no HELLO on the new link, its seq moved on while the cable
    was out), each cut in the middle of a frame: no bad frame, no gap (it showed `crc errors 5 · gaps 6 (747 lost)`)."""
    sphere = ScriptedSphere()
    stream = PacketStream()
    for link in range(7):
        data = b"".join(f for _, f in sphere.steps([("still", 0.2)]))
        if link:
            stream.restart()
        stream.feed(data[: len(data) - 7])  # unplugged in the middle of a frame
        for _ in sphere.steps([("still", 0.3)]):  # frames sent while unplugged
            pass
    s = stream.stats
    assert s.errors == 0 and s.seq_gaps == 0 and s.frames_lost == 0, s
    assert "bad 0 · gaps 0 (0 lost)" in _status_text(stream)


def test_garbage_is_counted_as_what_it_is():
    """30 s of noise at 115200 baud: every dropped chunk counts (it showed `crc errors 1`)."""
    import random

    rng = random.Random(3)
    stream = PacketStream()
    stream.feed(bytes(rng.randrange(256) for _ in range(11520 * 30)))
    s = stream.stats
    text = _status_text(stream)
    assert s.errors > 1000 and f"bad {s.errors} (" in text and "kB skipped" in text, text


def test_a_duplicate_is_not_255_lost_frames():
    sphere = ScriptedSphere()
    frames = [f for _, f in sphere.steps([("still", 0.1)])]
    stream = PacketStream()
    stream.feed(b"".join(frames[:5] + [frames[4]] + frames[5:]))
    assert "gaps 0 (0 lost) · duplicates 1" in _status_text(stream)


# ---- least privilege (host/packaging) ----


def test_udev_rules_give_nothing_to_groups_or_to_other_adapters():
    rules = [line for line in open(os.path.join(os.path.dirname(__file__), "..", "..", "host", "packaging",
                                                "70-sphere-mouse.rules")).read().splitlines()
             if line.strip() and not line.startswith("#")]
    assert rules and not any("GROUP=" in r for r in rules)  # no group input (every keyboard), no dialout
    for r in rules:
        if 'SUBSYSTEM=="tty"' in r or 'SUBSYSTEM=="hidraw"' in r:
            # seat access only for one adapter: its IDs and its serial number (or socket), not a whole chip family
            assert "ATTRS{idVendor}" in r and ("ATTRS{serial}" in r or "KERNELS" in r), r


def test_udev_rule_for_a_port():
    from serial.tools.list_ports_common import ListPortInfo

    from sphere.daemon.cli import udev_rule

    ftdi = ListPortInfo("/dev/ttyUSB0", skip_link_detection=True)
    ftdi.vid, ftdi.pid, ftdi.serial_number = 0x0403, 0x6001, "A50285BI"
    ch340 = ListPortInfo("/dev/ttyUSB1", skip_link_detection=True)
    ch340.vid, ch340.pid, ch340.location = 0x1A86, 0x7523, "1-1.2:1.0"
    assert 'ATTRS{idVendor}=="0403", ATTRS{idProduct}=="6001", ATTRS{serial}=="A50285BI"' in \
        udev_rule("/dev/ttyUSB0", lambda: [ftdi, ch340])
    assert 'KERNELS=="1-1.2:1.0"' in udev_rule("/dev/ttyUSB1", lambda: [ftdi, ch340])
    # the FTDI's latency timer to 1 ms for this adapter only; the CH340 has no such timer
    ftdi_lines = udev_rule("/dev/ttyUSB0", lambda: [ftdi, ch340]).splitlines()
    assert len(ftdi_lines) == 2 and ftdi_lines[1].startswith('ACTION=="add", SUBSYSTEM=="usb-serial", DRIVER=="ftdi_sio"')
    assert 'ATTRS{serial}=="A50285BI"' in ftdi_lines[1] and ftdi_lines[1].endswith('ATTR{latency_timer}="1"')
    assert "latency_timer" not in udev_rule("/dev/ttyUSB1", lambda: [ftdi, ch340])


def test_udev_rules_set_the_sphere_ftdi_latency_timer_only():
    rules = [line for line in open(os.path.join(os.path.dirname(__file__), "..", "..", "host", "packaging",
                                                "70-sphere-mouse.rules")).read().splitlines()
             if "latency_timer" in line and not line.startswith("#")]
    assert len(rules) == 1 and 'ATTR{latency_timer}="1"' in rules[0] and 'DRIVER=="ftdi_sio"' in rules[0]
    assert "ATTRS{serial}" in rules[0]  # this sphere's adapter, not every FTDI chip


@pytest.mark.slow
def test_a_connection_flood_does_not_cost_the_sphere(tmp_path):
    """The daemon with its 3-D server and a sphere on a serial port: 2,000 connection attempts (200 held open)
    while the sphere is unplugged and plugged in again; the port reopens and the pointer moves on (1,100 held
    connections used to exhaust the descriptors so that the port could not reopen)."""
    from test_mouse_serial import LEFT, RIGHT, FakeSphere, fast_serial, wait_for

    from sphere.daemon.stream3d import OrientationStream

    link = tmp_path / "sphere"
    dev = FakeSphere(link, LEFT)
    source = fast_serial(str(link), link_timeout_s=30.0)
    stream = OrientationStream("127.0.0.1", 0, rate_hz=60, max_clients=16)
    stream.start()
    cfg = Config().with_overrides({"gyro": {"still_time_s": 0.3}}, "t")
    backend = RecordingBackend()
    daemon = SphereMouse(cfg, source, backend, stream=stream, log=lambda m: None)
    thread = threading.Thread(target=daemon.run, daemon=True)
    thread.start()
    held = []
    try:
        assert wait_for(lambda: backend.x <= -238)
        dev.unplug()
        held = _flood(stream.port)
        dev = FakeSphere(link, RIGHT)
        assert wait_for(lambda: source.connects == 2)
        assert wait_for(lambda: backend.x >= -2), backend.x
        assert stream.refused >= 1000  # beyond max_clients, refused at once
    finally:
        for c in held:
            c.close()
        daemon.stop()
        thread.join(5)
        stream.stop()
        dev._stop.set()


def test_a_magnetometer_whose_first_conversion_has_not_come_is_not_a_fault():
    """After a HELLO the first RAW_SAMPLEs lack mag_ok until the HMC5883L's first single measurement is read
    (spec §4.2: its values are not valid yet): no "not answering", no "answers again". A sensor the HELLO says
    was not found at start is said once; one that stops later is said, and said again when it answers."""
    logs = []
    cfg = Config().with_overrides({"outputs.page": {"enabled": False}}, "t")
    d = SphereMouse(cfg, source=None, backend=RecordingBackend(), log=logs.append)
    stream = PacketStream()
    frames = [encode_frame(hello_packet(), 0)]
    flags = [0x0B, 0x0B, 0x0F, 0x0F]  # accel + gyro, then the magnetometer's first conversion
    frames += [encode_frame(_raw(1_000_000 + 5000 * i, (0, 0, 0), f), i) for i, f in enumerate(flags, 1)]
    feed_bytes(d, b"".join(frames), stream)
    assert logs == [] and d.sensors_missing == ()
    # the device starts again (a reset): the same, again no message
    frames = [encode_frame(hello_packet(), 0)]
    frames += [encode_frame(_raw(5000 * i, (0, 0, 0), f), i) for i, f in enumerate(flags, 1)]
    feed_bytes(d, b"".join(frames), stream)
    assert logs == []
    # the magnetometer stops answering, then answers again
    frames = [encode_frame(_raw(100_000 + 5000 * i, (0, 0, 0), f), i) for i, f in enumerate([0x0B] * 3 + [0x0F], 5)]
    feed_bytes(d, b"".join(frames), stream)
    assert logs == ["the sphere reports its magnetometer not answering (RAW_SAMPLE flags)",
                    "the sphere's magnetometer answers again"]
    # a sphere without a magnetometer: said once, at its first sample
    logs.clear()
    hello = hello_packet()
    hello.sensors_found = 0x03
    frames = [encode_frame(hello, 0)] + [encode_frame(_raw(5000 * i, (0, 0, 0), 0x03), i) for i in range(1, 50)]
    feed_bytes(d, b"".join(frames), PacketStream())
    assert logs == ["the sphere found no magnetometer at start (HELLO)"]
    assert d.sensors_missing == ("magnetometer",)
