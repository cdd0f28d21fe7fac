"""The virtual camera: the ball's image against the outline geometry, time stamps, exposure, occlusion."""

from __future__ import annotations

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2", reason="opencv-python-headless (the camera extra) is part of the setup")

from sphere.camera import render  # noqa: E402
from sphere.camera import sphere_geometry as geom  # noqa: E402
from sphere.camera.detect import hue_projection  # noqa: E402
from sphere.camera.model import Camera  # noqa: E402

CAM = Camera.webcam()


def _scene(**kw):
    return render.Scene(CAM, render.look_at([0, 0, 0], [1, 0, 0]), np.zeros(3), seed=2, **kw)


def _ball_pixels(img, hue=120.0):
    along, across, bright = hue_projection(img, hue)
    return (along > 0.45 * bright) & (np.abs(across) < 0.35 * along) & (bright > 30)


@pytest.mark.parametrize("p_cam", [(0.0, 0.0, 0.6), (0.3, 0.2, 0.7), (-0.4, 0.1, 1.2)])
def test_the_ball_covers_the_projected_outline_of_the_sphere(p_cam):
    sc = _scene()
    p_cam = np.asarray(p_cam)
    img = sc.render(0.2, 0.008, lambda t: sc.cam_pos + sc.R_wc @ p_cam, 0)
    outline = CAM.project(np.c_[geom.outline_points(p_cam, 0.04, 180), np.ones(180)])
    area = cv2.contourArea(outline.astype(np.float32))
    x0, y0 = np.floor(outline.min(0)).astype(int) - 6
    x1, y1 = np.ceil(outline.max(0)).astype(int) + 6
    mask = _ball_pixels(img[y0:y1, x0:x1])
    assert abs(mask.sum() - area) < 0.04 * area + 2 * np.sqrt(area)
    # and the mask's centroid is the outline's, not the projected centre's (they differ off the axis)
    ys, xs = np.nonzero(mask)
    m = cv2.moments(outline.astype(np.float32))
    assert np.hypot(xs.mean() + x0 - m["m10"] / m["m00"], ys.mean() + y0 - m["m01"] / m["m00"]) < 0.5


def test_frames_arrive_a_capture_latency_after_their_exposure():
    sc = _scene()
    start, mid, arrival, exposure = sc.frame_times(0.0, 10.0)
    assert len(start) == 300
    assert np.allclose(np.diff(start).mean(), 1 / 30, atol=1e-4) and np.diff(start).std() > 5e-4  # jitter
    lat = arrival - mid
    assert lat.min() >= 0.035 and 0.037 < lat.mean() < 0.045 and lat.max() < 0.1
    # auto-exposure: the gain changes in steps, the exposure time with it
    assert exposure.max() / exposure.min() > 1.3
    g = np.array([sc.gain(t) for t in start])
    assert g.std() > 0.05


def test_auto_exposure_changes_the_brightness_of_the_whole_frame():
    sc = _scene()
    t = np.arange(0, 10, 0.1)
    g = np.array([sc.gain(x) for x in t])
    a, b = t[np.argmin(g)], t[np.argmax(g)]
    img_a = sc.render(a, 0.008, lambda _t: np.array([1.0, 0, 0]), 0).astype(float)
    img_b = sc.render(b, 0.008, lambda _t: np.array([1.0, 0, 0]), 1).astype(float)
    assert img_b.mean() / img_a.mean() == pytest.approx(g.max() / g.min(), rel=0.1)


def test_a_hand_hides_the_ball_and_it_can_leave_the_frame():
    p = np.array([0.0, 0.0, 0.8])
    full = _scene(occlusions=[render.Occlusion(0.0, 1.0, cover=1.0)])
    img = full.render(0.5, 0.008, lambda t: full.cam_pos + full.R_wc @ p, 0)
    assert _ball_pixels(img[200:280, 280:360]).sum() < 20
    part = _scene(occlusions=[render.Occlusion(0.0, 1.0, cover=0.35)])
    img = part.render(0.5, 0.008, lambda t: part.cam_pos + part.R_wc @ p, 0)
    clear = _scene().render(0.5, 0.008, lambda t: part.cam_pos + part.R_wc @ p, 0)
    n_part, n_clear = _ball_pixels(img[200:280, 280:360]).sum(), _ball_pixels(clear[200:280, 280:360]).sum()
    assert 0.45 < n_part / n_clear < 0.85
    out = _scene().render(0.5, 0.008, lambda t: np.array([1.0, 2.0, 0.0]), 0)  # 63° to the side
    assert out.shape == (480, 640, 3)


@pytest.mark.slow
def test_chessboard_images_are_found_by_opencv():
    R = cv2.Rodrigues(np.array([0.3, -0.4, 0.1]))[0]
    img = render.render_board(CAM, R, np.array([-0.1, -0.07, 0.5]), 9, 6, 0.025)
    ok, corners = cv2.findChessboardCorners(img, (8, 5))
    assert ok
    # the first inner corner is at board (1, 1) squares
    truth = CAM.project((R @ np.array([0.025, 0.025, 0.0]) + np.array([-0.1, -0.07, 0.5]))[None])[0]
    d = np.linalg.norm(corners.reshape(-1, 2) - truth, axis=1).min()
    assert d < 1.0
