"""The spacenav output (a 3-D mouse for libspnav programs) against Debian's real libspnav: through ctypes
and through libspnav-dev's own examples/simple.c, over both protocol versions, driven by sphere-mouse
replaying the virtual sphere's turn (tests/captures/sim_turn_90.bin); the protocol's corner cases; hostile
clients (random bytes, 1,000 connects, one that never reads)."""

import math
import os
import random
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest

from outputs_bench import HERE, compile_simple, figures, libspnav_missing, run_spnav_hostile, run_turn
from sphere import quaternion as quat
from sphere.daemon.config import Config, parse_set
from sphere.daemon.outputs.base import OutputUnavailable
from sphere.daemon.outputs.fanout import attach
from sphere.daemon.outputs import spacenav as sn

needs_libspnav = pytest.mark.skipif(libspnav_missing() is not None, reason=str(libspnav_missing()))


@pytest.fixture(scope="module")
def simple_example(tmp_path_factory):
    if libspnav_missing():
        pytest.skip(libspnav_missing())
    return compile_simple(tmp_path_factory.mktemp("spnav"))


@pytest.mark.slow
@needs_libspnav
@pytest.mark.parametrize("protocol", [1, 0])
def test_a_replayed_turn_reaches_libspnav_clients(tmp_path, simple_example, protocol):
    f = figures(run_turn(tmp_path, protocol, simple=simple_example))
    assert f["protocol"] == protocol
    assert f["axes"] == 6 and f["buttons"] == (2 if protocol else 2)  # v0: libspnav's defaults, also 6 and 2
    for client in ("ctypes", "simple"):
        m = f[client]
        assert m["events_per_s"] >= 60, (client, m)
        assert client == "simple" or m["arrival_per_s"] >= 60, (client, m)  # stdbuf's pipe and a reader thread
        assert m["still_events"] == 0 and m["zero_events"] == 1, (client, m)
        assert m["zero_after_stop_ms"] <= 250, (client, m)  # wall clock: ~20 ms on an idle machine (the bench)
        assert client == "simple" or m["zero_after_stop_device_ms"] <= 50, (client, m)
        x, y, z, rx, ry, rz = m["sums"]
        assert 1571 * 0.95 < ry < 1571 * 1.05 and abs(rx) < 30 and abs(rz) < 30 and x == y == z == 0, (client, m)
    assert abs(f["moveobj_deg"] - 90.0) <= 5.0 and f["moveobj_axis"][1] > 0.99, f  # about +y: turned left
    taps = [(0, 1), (0, 0), (0, 1), (0, 0), (1, 1), (1, 0)]  # single tap; double tap = a single, then button 1
    assert f["button_events"] == taps and f["simple"]["button_events"] == taps
    if protocol == 1:
        assert f["device_name"] == "MARG sphere" and f["simple"]["device_line"] == "Device: MARG sphere"
    assert f["simple"]["protocol_line"] == f"spacenav AF_UNIX protocol version: {protocol}"
    assert f["simple_rc"] == 0  # the example's spnav_wait_event returned 0 when the daemon closed: it exited


def _client(sock_path, seconds="8"):
    env = dict(os.environ, SPNAV_SOCKET=str(sock_path))
    return subprocess.Popen([sys.executable, str(HERE / "spnav_client.py"), seconds], env=env, stdout=subprocess.PIPE,
                            text=True)


def _turned(axis, deg):
    return tuple(quat.from_axis_angle(axis, math.radians(deg)))


@needs_libspnav
def test_puck_mapping_signs_through_libspnav(tmp_path):
    """Tilt held from the centre is a steady rate along the same axis; back at the centre one zero event."""
    import json

    path = tmp_path / "puck.sock"
    out = sn.SpacenavOutput(str(path), log=lambda m: None, mapping="puck", rate_hz=100.0)
    out.mode("3d")
    client = _client(path, "20")  # it ends when the server closes
    t = 0
    try:
        deadline = time.monotonic() + 10
        while not out.server.clients and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.5)  # its handshake and queries done
        x, y, z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
        for q in [(1.0, 0.0, 0.0, 0.0)] * 5 + [_turned(z, 20.0)] * 20 + [(1.0, 0.0, 0.0, 0.0)] * 5 + \
                [_turned(y, -20.0)] * 20 + [_turned(x, 20.0)] * 20 + [(1.0, 0.0, 0.0, 0.0)] * 5:
            out.motion((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), t, q)
            t += 5000
            time.sleep(0.005)
        time.sleep(0.3)
    finally:
        out.close()
        lines = [json.loads(l) for l in client.communicate(timeout=10)[0].splitlines()]
    motion = [r["v"] for r in lines if r["kind"] == "motion"]
    left, nose_up, roll = motion[:10], motion[11:21], motion[21:31]
    level = sn.SpnavMotion().full_scale * ((20 - 3) / (30 - 3)) ** 1.5
    assert all(v[:4] == [0, 0, 0, 0] and abs(v[4] - level) <= 1 and v[5] == 0 for v in left), left
    assert motion[10] == [0] * 6  # back at the centre: one zero event
    assert all(abs(v[3] - level) <= 1 and v[:3] == [0, 0, 0] and v[4:] == [0, 0] for v in nose_up), nose_up
    assert all(abs(v[2] - level) <= 1 and v[3:] == [0, 0, 0] for v in roll), roll  # roll right: zoom in (+z)
    assert motion[-1] == [0] * 6 and len(motion) == 32


def _session(**kw):
    return sn.SpnavSession("MARG sphere with a name longer than one chunk", "/run/user/1000/spnav.sock", **kw)


def test_protocol_corner_cases():
    s = _session()
    assert s.feed(struct.pack("=i", 0x7FAA5507)) == struct.pack("=i", 0x7FAA5501)  # asks for v7: gets v1
    assert s.proto == 1 and s.evmask == 0x07
    # the name comes back in 24-byte chunks, data[6] the remaining length, bit 16 on the later chunks
    reply = s.feed(struct.pack("=8i", 0x7FAA2000, 0, 0, 0, 0, 0, 0, 0))
    recs = [struct.unpack("=i24si", reply[i:i + 32]) for i in range(0, len(reply), 32)]
    assert [r[0] for r in recs] == [0x7FAA2000] * 2 and [r[2] for r in recs] == [45, 21 | 0x10000]
    assert b"".join(r[1] for r in recs)[:45] == b"MARG sphere with a name longer than one chunk"
    assert s.feed(struct.pack("=8i", 0x1000, *struct.unpack("=6i", b"FreeCAD".ljust(24, b"\0")), 7)) == b""
    assert s.client_name == b"FreeCAD"  # SET_NAME is never answered
    r = struct.unpack("=8i", s.feed(struct.pack("=8i", 0x7FAA3000, 0, 0, 0, 0, 0, 0, 0)))
    assert r[0] == 0x7FAA3000 and r[7] < 0  # spacenavd's configuration: failure at once
    r = struct.unpack("=8i", s.feed(struct.pack("=8i", 0x7FAA2004, 0, 0, 0, 0, 0, 0, 0)))
    assert r[7] < 0  # no USB id
    half = struct.pack("=8i", 0x7FAA1001, struct.unpack("=i", struct.pack("=f", 2.0))[0], 0, 0, 0, 0, 0, 0)
    assert s.feed(half[:10]) == b"" and struct.unpack("=8i", s.feed(half[10:]))[7] == 0  # split across reads
    assert s.sensitivity == 2.0 and struct.unpack("=8i", s.motion([0, 0, 0, 0, 5, 0], 10))[5] == 10
    assert s.feed(struct.pack("=8i", 0x12345678, 0, 0, 0, 0, 0, 0, 0)) == b"" and s.garbage  # not a request
    v0 = _session()
    assert v0.feed(struct.pack("=f", 0.5)) == b"" and v0.proto == 0 and v0.sensitivity == 0.5
    assert struct.unpack("=8i", v0.motion([1, 2, 3, 400, -500, 6], 8)) == (0, 0, 1, 1, 200, -250, 3, 8)
    old = _session(max_proto=0)  # a daemon before 1.0: the handshake (a NaN) goes unanswered
    assert old.feed(struct.pack("=i", 0x7FAA5501)) == b"" and old.proto == 0 and old.garbage is None
    assert old.feed(struct.pack("=f", 1.0)) == b"" and old.sensitivity == 1.0


def test_a_live_socket_is_not_taken_over_and_a_stale_one_is(tmp_path):
    path = str(tmp_path / "spnav.sock")
    held = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    held.bind(path)
    held.listen(1)  # someone (spacenavd) answers here
    try:
        with pytest.raises(OutputUnavailable, match="answers on .*spnav.sock; stop it or set"):
            sn.SpnavServer(path, "x")
    finally:
        held.close()
    assert sn.socket_owner(path) == "stale"  # left behind by a program that ended
    s = sn.SpnavServer(path, "x")
    assert sn.socket_owner(path) == "live"
    s.close()
    assert not os.path.exists(path)
    Path(path).write_text("not a socket")
    with pytest.raises(OutputUnavailable, match="not a socket"):
        sn.SpnavServer(path, "x")


def _rss_kib():
    with open("/proc/self/status") as f:
        return next(int(l.split()[1]) for l in f if l.startswith("VmRSS:"))


def test_hostile_clients_leave_the_others_served(tmp_path):
    """Random bytes: that client alone is dropped. 1,000 connects: served and gone. One that never reads:
    the daemon's call never blocks, its queue stays bounded, and a well-behaved client gets every event."""
    path = str(tmp_path / "h.sock")
    logs = []
    server = sn.SpnavServer(path, "MARG sphere", log=logs.append)
    try:
        good = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        good.connect(path)
        good.sendall(struct.pack("=i", 0x7FAA5501))
        assert good.recv(4) == struct.pack("=i", 0x7FAA5501)
        rng = random.Random(26)
        noisy = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        noisy.connect(path)
        noisy.sendall(bytes([0x42, 0x13, 0x37, 0xFF]) + rng.randbytes(4000))
        for _ in range(1000):
            c = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            c.connect(path)
            c.close()
        deadline = time.monotonic() + 20
        while len(server.clients) > 1 and time.monotonic() < deadline:  # each of them seen gone
            time.sleep(0.01)
        assert len(server.clients) == 1, logs
        mute = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        mute.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        mute.connect(path)
        mute.sendall(struct.pack("=i", 0x7FAA5501))
        time.sleep(0.3)
        assert noisy.recv(100) == b""  # dropped
        assert any("does not speak the protocol" in m for m in logs)
        rss0 = _rss_kib()
        got = 0
        good.setblocking(False)
        for i in range(20000):  # 200 s of events at 100 Hz
            server.motion([0, 0, 0, 1, i % 7, 2], 10)
            try:
                got += len(good.recv(65536))
            except BlockingIOError:
                pass
        deadline = time.monotonic() + 5
        while got < 20000 * 32 and time.monotonic() < deadline:
            try:
                got += len(good.recv(65536))
            except BlockingIOError:
                time.sleep(0.01)
        with server.lock:
            queued = [len(c.out) for c in server.clients.values()]
        assert got == 20000 * 32, logs  # every event reached the client that reads
        assert max(queued) <= sn.HARD_LIMIT  # a blocking send would have hung the loop above for good
        assert _rss_kib() - rss0 < 2048
        assert len(server.clients) == 2, logs  # the good one and the mute one
    finally:
        server.close()


def test_spacenav_through_the_daemons_seam(tmp_path):
    """Off by default; on, it starts from its section; a bad value is one clear line."""
    cfg = Config()
    assert cfg["outputs.spacenav"].enabled is False and cfg["outputs.spacenav"].mapping == "puck"
    sock = tmp_path / "d.sock"
    out = attach(Config().with_overrides(parse_set(["outputs.page.enabled=false", "outputs.spacenav.enabled=true",
                                                    f"outputs.spacenav.socket={sock}"]), "test"))
    try:
        assert [o.NAME for o in out.outputs] == ["spacenav"] and sock.exists()
    finally:
        out.stop()
    assert not sock.exists()
    from sphere.daemon.config import ConfigError

    with pytest.raises(ConfigError, match="mapping"):
        Config().with_overrides(parse_set(["outputs.spacenav.mapping=orbit"]), "test")


def test_a_running_spacenavd_is_said_in_one_line(tmp_path, monkeypatch):
    system = tmp_path / "spnav.sock"
    monkeypatch.setattr(sn, "SYSTEM_SOCKET", str(system))
    ours = str(tmp_path / "ours.sock")
    assert "sphere service install --spnav-link" in sn.system_socket_note(ours)  # no system socket yet
    held = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    held.bind(str(system))
    held.listen(1)
    try:
        note = sn.system_socket_note(ours)
        assert note.startswith(f"spacenav: a running spacenavd owns {system};") and "\n" not in note
        with pytest.raises(OutputUnavailable, match="a running spacenavd answers on"):
            sn.SpnavServer(str(system), "x")
    finally:
        held.close()


@pytest.mark.slow  # a calm and a hostile replay at the sphere's pace: ~20 s
@needs_libspnav
def test_hostile_clients_during_a_replay_leave_the_pointer_and_a_real_client_alone(tmp_path):
    h = run_spnav_hostile(tmp_path)
    calm, hostile = h["calm"], h["hostile"]
    assert calm["rc"] == hostile["rc"] == 0 and not hostile["traceback"], h
    assert hostile["moves"] == calm["moves"] > 100, h  # the pointer did what it does without them
    for g in (calm["good"], hostile["good"]):  # libspnav's client got the whole turn and its stop
        assert 1571 * 0.95 < g["sums"][4] < 1571 * 1.05 and g["zero_events"] == 1 and g["still_events"] == 0, h
    assert hostile["dropped_logged"] == 1, h  # the random bytes; the mute one is kept, its queue bounded
    assert hostile["rss_growth_kib"] < calm["rss_growth_kib"] + 2048, h
