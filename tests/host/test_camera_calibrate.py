"""`sphere camera calibrate` on chessboard images from the virtual camera: the known intrinsics come back."""

from __future__ import annotations

import json

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2", reason="opencv-python-headless (the camera extra) is part of the setup")

from sphere.camera import render  # noqa: E402
from sphere.camera.model import Camera  # noqa: E402
from sphere.cli import main  # noqa: E402

TRUE = Camera(640, 480, 560.0, 556.0, 322.5, 236.0, (-0.15, 0.08, 0.001, -0.0006, 0.0))


def _views(tmp_path, n=10, texture=None):
    rng = np.random.default_rng(11)
    for k in range(n):
        rv = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3)])
        R = cv2.Rodrigues(rv)[0]
        centre = np.array([rng.uniform(-0.12, 0.12), rng.uniform(-0.08, 0.08), rng.uniform(0.45, 0.6)])
        t = centre - R @ np.array([0.125, 0.0875, 0.0])  # the board's middle at `centre`
        img = render.render_board(TRUE, R, t, 9, 6, 0.025, seed=k, texture=texture)
        cv2.imwrite(str(tmp_path / f"view{k:02d}.png"), img)


@pytest.mark.slow
def test_calibrate_recovers_the_intrinsics(tmp_path, capsys):
    _views(tmp_path)
    (tmp_path / "not-a-board.png").write_bytes(cv2.imencode(".png", np.full((480, 640), 128, np.uint8))[1].tobytes())
    out = tmp_path / "cam.json"
    assert main(["camera", "calibrate", str(tmp_path), "--board", "9x6", "--square-mm", "25", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "1 without the board (not-a-board.png)" in text
    cam = Camera.load(out)
    assert cam.fx == pytest.approx(TRUE.fx, rel=0.005) and cam.fy == pytest.approx(TRUE.fy, rel=0.005)
    assert abs(cam.cx - TRUE.cx) < 2.0 and abs(cam.cy - TRUE.cy) < 2.0
    assert cam.dist[0] == pytest.approx(TRUE.dist[0], abs=0.02)
    assert cam.rms_px < 0.3
    # what matters downstream: the rays of the calibrated camera match the true ones
    v, u = np.mgrid[20:480:40, 20:640:40]
    px = np.stack([u.ravel(), v.ravel()], 1).astype(float)
    ang = np.degrees(np.arccos(np.clip(np.sum(cam.rays(px) * TRUE.rays(px), axis=1), -1, 1)))
    assert ang.max() < 0.1
    assert json.loads(out.read_text())["width"] == 640


def test_calibrate_says_what_is_wrong(tmp_path, capsys):
    assert main(["camera", "calibrate", str(tmp_path / "nothing")]) == 2
    assert "does not exist" in capsys.readouterr().err
    (tmp_path / "a.png").write_bytes(cv2.imencode(".png", np.zeros((48, 64), np.uint8))[1].tobytes())
    assert main(["camera", "calibrate", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert "found in 0 of 1 images" in err and "Traceback" not in err
    with pytest.raises(SystemExit) as e:  # a usage error: exit 2
        main(["camera", "calibrate", str(tmp_path), "--board", "nine"])
    assert e.value.code == 2 and "squares across" in capsys.readouterr().err


@pytest.mark.slow
def test_calibrate_with_a_charuco_board(tmp_path, capsys):
    from sphere.camera.intrinsics import charuco_board

    board = charuco_board(9, 6, 0.025, 0.018).generateImage((900, 600), marginSize=0)
    _views(tmp_path, texture=board)
    out = tmp_path / "cam.json"
    assert main(["camera", "calibrate", str(tmp_path), "--board", "9x6", "--square-mm", "25", "--charuco", "18",
                 "-o", str(out)]) == 0
    cam = Camera.load(out)
    assert cam.fx == pytest.approx(TRUE.fx, rel=0.005) and abs(cam.cx - TRUE.cx) < 2.0 and cam.rms_px < 0.3
    # a plain chessboard given as ChArUco: no markers, a clear line
    (tmp_path / "plain").mkdir()
    _views(tmp_path / "plain", n=5)
    assert main(["camera", "calibrate", str(tmp_path / "plain"), "--charuco", "18"]) == 1
    assert "ChArUco board was found in 0 of 5" in capsys.readouterr().err
