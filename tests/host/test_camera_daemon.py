"""The camera's [camera] settings for sphere-mouse and the object the daemon keeps (the wiring into the
daemon's loop is the daemon's: see sphere.camera.daemon_source)."""

from __future__ import annotations

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2", reason="opencv-python-headless (the camera extra) is part of the setup")

from sphere.daemon import config  # noqa: E402


@pytest.fixture(autouse=True)
def daemon_source():
    """[camera] declared for these tests only: until the daemon lists the module in its CONTRIBUTORS, the
    section must not leak into other tests (the key reference in the docs is compared with the sections)."""
    import importlib

    had = "camera" in config.SECTIONS
    mod = importlib.import_module("sphere.camera.daemon_source")
    config.register_section("camera", mod.CameraSettings)
    yield mod
    if not had:
        config.SECTIONS.pop("camera", None)
        config._KINDS.pop("camera", None)


def test_camera_section_defaults_to_no_camera(daemon_source):
    cfg = config.Config()
    assert cfg["camera"].source == "" and daemon_source.CameraPosition.from_config(cfg) is None


def test_bad_camera_settings_are_one_clear_line(tmp_path, daemon_source):
    p = tmp_path / "c.toml"
    p.write_text("[camera]\nhue_deg = 400\n")
    with pytest.raises(config.ConfigError, match=r"hue_deg.*\[0, 360\)"):
        config.load(p)
    cfg = config.Config({"camera": {"source": str(tmp_path / "missing.avi")}})
    with pytest.raises(config.ConfigError, match=r"\[camera\] cannot open video file"):
        daemon_source.CameraPosition.from_config(cfg)


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
    t = [0.0]
    pos = daemon_source.CameraPosition.from_config(cfg)
    pos.clock = lambda: t[0]
    pos.live.source._thread.join(timeout=30)
    got = None
    for k in range(140):  # 0.7 s of sensor samples at 200 Hz (the 20 frames), the sphere lying still
        t[0] = k * 0.005
        got = pos.update([1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 9.81]) or got
    pos.close()
    assert got is not None
    # MJPG's 4:2:0 chroma moves the colour edge: ~1 % of the distance in depth (4 mm on the raw frames)
    err = np.asarray(got) - sc.to_camera([0.9, 0.05, 0.0])
    assert np.abs(err[:2]).max() < 0.003 and abs(err[2]) < 0.015
