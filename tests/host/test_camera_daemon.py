"""The camera's [camera] settings for sphere-mouse, the object the daemon keeps, and the daemon end to end: a
replayed capture with a video of the ball gives positions in the 3-D stream."""

from __future__ import annotations

import time

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2", reason="opencv-python-headless (the camera extra) is part of the setup")

from sphere.daemon import config  # noqa: E402


@pytest.fixture
def daemon_source():
    """[camera] is one of the daemon's sections (sphere.daemon.config.PARTS)."""
    import importlib

    assert "camera" in config.sections() and "camera" in config.PARTS
    return importlib.import_module("sphere.camera.daemon_source")


def test_camera_section_defaults_to_no_camera(daemon_source):
    cfg = config.Config()
    assert cfg["camera"].source == "" and daemon_source.CameraPosition.from_settings(cfg["camera"]) is None


def test_bad_camera_settings_are_one_clear_line(tmp_path, daemon_source):
    p = tmp_path / "c.toml"
    p.write_text("[camera]\nhue_deg = 400\n")
    with pytest.raises(config.ConfigError, match=r"hue_deg.*\[0, 360\)"):
        config.load(p)
    cfg = config.Config({"camera": {"source": str(tmp_path / "missing.avi")}})
    with pytest.raises(daemon_source.CameraUnavailable, match=r"\[camera\] cannot open video file"):
        daemon_source.CameraPosition.from_settings(cfg["camera"])


@pytest.mark.slow
def test_a_video_source_gives_positions(tmp_path, daemon_source):
    from sphere.camera import render
    from sphere.camera.model import Camera

    cam = Camera.webcam()
    sc = render.Scene(cam, render.look_at([0, 0, 0], [1, 0, 0]), np.zeros(3))
    path = str(tmp_path / "still.avi")
    out = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (640, 480))
    for k in range(20):  # a still ball 0.9 m in front of the lens
        out.write(sc.render(k / 30, 0.008, lambda t: np.array([0.9, 0.05, 0.0]), k))
    out.release()
    cfg = config.Config({"camera": {"source": path}})
    pos = daemon_source.CameraPosition.from_settings(cfg["camera"])
    got = None
    end = time.monotonic() + 20
    while pos.live.source.running and time.monotonic() < end:  # the file plays at 30 fps, as a webcam would
        got = pos.update([1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 9.81]) or got  # the sphere lying still
        time.sleep(0.005)
    pos.close()
    assert got is not None
    # MJPG's 4:2:0 chroma moves the colour edge: ~1 % of the distance in depth (4 mm on the raw frames)
    err = np.asarray(got) - sc.to_camera([0.9, 0.05, 0.0])
    assert np.abs(err[:2]).max() < 0.003 and abs(err[2]) < 0.015


@pytest.mark.slow
def test_sphere_mouse_streams_the_ball_position_from_a_video(tmp_path):
    """sphere-mouse --replay CAPTURE --camera VIDEO: the 3-D stream's messages carry the ball's position (the
    daemon's whole path: config, the camera thread, the fusion per RAW_SAMPLE, the pose filter, the WebSocket)."""
    import asyncio
    import json
    import os
    import re
    import subprocess
    import sys
    import time
    from pathlib import Path

    from websockets.asyncio.client import connect

    from sphere.camera import render
    from sphere.camera.model import Camera

    cam = Camera.webcam()
    sc = render.Scene(cam, render.look_at([0, 0, 0], [1, 0, 0]), np.zeros(3))
    truth = np.array([0.9, 0.05, 0.0])
    video = str(tmp_path / "still.avi")
    out = cv2.VideoWriter(video, cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (640, 480))
    for k in range(240):  # 8 s of a still ball 0.9 m in front of the lens
        out.write(sc.render(k / 30, 0.008, lambda t: truth, k))
    out.release()
    capture = Path(__file__).resolve().parents[1] / "captures" / "sim_mag_fault.bin"  # 6 s, the sphere still
    proc = subprocess.Popen([sys.executable, "-m", "sphere.mouse", "--replay", str(capture), "--camera", video,
                             "--backend", "log", "--stream-port", "0", "--quiet"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "HOME": str(tmp_path)})
    try:
        port = None
        deadline = time.monotonic() + 60
        while port is None and time.monotonic() < deadline:
            line = proc.stderr.readline()
            assert line, "sphere-mouse ended before serving the 3-D stream"
            m = re.search(r"ws://[\d.]+:(\d+)/ws", line)
            port = int(m.group(1)) if m else None

        async def positions():
            got = []
            async with connect(f"ws://127.0.0.1:{port}/ws") as ws:
                end = time.monotonic() + 8
                while time.monotonic() < end and len(got) < 50:
                    try:
                        msg = json.loads(await asyncio.wait_for(ws.recv(), 1.0))
                    except asyncio.TimeoutError:
                        continue
                    except Exception:
                        break  # the replay ended and the daemon closed the stream
                    if msg.get("type") == "orientation" and msg.get("position") is not None:
                        got.append(msg["position"])
            return got

        got = asyncio.run(positions())
    finally:
        proc.terminate()
        proc.wait(timeout=20)
    assert len(got) >= 10, f"only {len(got)} stream messages with a position"
    err = np.asarray(got[-10:]) - sc.to_camera(truth)
    # MJPG's 4:2:0 chroma moves the colour edge: ~1 % of the distance in depth
    assert np.abs(err[:, :2]).max() < 0.005 and np.abs(err[:, 2]).max() < 0.02, err


def test_without_opencv_a_camera_is_one_clear_line(tmp_path):
    """`sphere capture --camera` and `sphere-mouse --camera` on a machine without the camera extra: one line
    naming the extra, no traceback (the camera's modules import without OpenCV; it is checked where they are)."""
    import os
    import subprocess
    import sys

    blocked = tmp_path / "blocked"
    blocked.mkdir()
    (blocked / "cv2.py").write_text("raise ImportError(\"No module named 'cv2'\")\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(blocked), os.environ.get("PYTHONPATH", "")]))
    from sphere.daemon.scripted_sphere import script_bytes

    capture = tmp_path / "still.bin"
    capture.write_bytes(script_bytes([("still", 0.5)]))
    master, slave = os.openpty()
    try:
        runs = [[sys.executable, "-m", "sphere.cli", "capture", "--port", os.ttyname(slave), "--camera", "0",
                 "--seconds", "1", "--out", str(tmp_path / "session")],
                [sys.executable, "-m", "sphere.mouse", "--replay", str(capture), "--camera", "0", "--backend", "log",
                 "--no-stream", "--config", os.devnull]]
        for argv in runs:
            r = subprocess.run(argv, capture_output=True, text=True, timeout=60, env=env)
            lines = [ln for ln in r.stderr.splitlines() if "needs OpenCV" in ln]
            assert r.returncode == 2 and len(lines) == 1 and "pip install -e '.[camera]'" in lines[0], r.stderr
            assert "Traceback" not in r.stderr, r.stderr
    finally:
        os.close(master)
        os.close(slave)
    assert not (tmp_path / "session").exists()  # nothing half-written
