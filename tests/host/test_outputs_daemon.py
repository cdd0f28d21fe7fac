"""sphere-mouse with an output switched on in its config: a replayed capture reaches a UDP socket as
OpenTrack datagrams, and the daemon says where it sends them."""

import socket
import struct
import subprocess
import sys

from sphere.daemon.scripted_sphere import script_bytes


def test_sphere_mouse_sends_opentrack_datagrams(tmp_path):
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(0.5)
    port = rx.getsockname()[1]
    config = tmp_path / "config.toml"
    config.write_text(f"[outputs.opentrack]\nenabled = true\nport = {port}\nrate_hz = 1000\n")
    cap = tmp_path / "turn.cap"
    cap.write_bytes(script_bytes([("still", 0.5), ("turn", (0, 0, 1), 60.0, 1.0), ("still", 0.3)]))  # 60 °/s left, 1 s
    try:
        r = subprocess.run([sys.executable, "-m", "sphere.mouse", "--config", str(config), "--replay", str(cap),
                            "--speed", "0", "--backend", "log", "--no-stream"], capture_output=True, text=True, timeout=120)
        datagrams = []
        try:
            while True:
                datagrams.append(rx.recv(100))
        except socket.timeout:
            pass
    finally:
        rx.close()
    assert r.returncode == 0, r.stderr
    assert f"output opentrack: UDP to 127.0.0.1:{port}" in r.stderr
    assert len(datagrams) > 100 and all(len(d) == 48 for d in datagrams)
    poses = [struct.unpack("<6d", d) for d in datagrams]
    assert all(p[:3] == (0.0, 0.0, 0.0) for p in poses)  # no pose source: no position
    # turned 60° left: the yaw the host's filter gives (it may take part of a turn about the vertical for gyro bias)
    yaws = [p[3] for p in poses]
    assert abs(yaws[0]) < 1.0 and 30.0 < yaws[-1] < 70.0, (poses[0], poses[-1])
    assert all(b >= a - 0.5 for a, b in zip(yaws, yaws[1:]))  # one way only
    assert all(abs(p[4]) < 2.0 and abs(p[5]) < 2.0 for p in poses)  # no pitch, no roll
