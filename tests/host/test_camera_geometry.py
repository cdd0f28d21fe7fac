"""The camera model and the sphere's perspective image, checked against OpenCV and against first principles."""

from __future__ import annotations

import numpy as np
import pytest

from sphere.camera import sphere_geometry as geom
from sphere.camera.model import Camera, CameraFileError

cv2 = pytest.importorskip("cv2", reason="opencv-python-headless (the camera extra) is part of the setup")


def test_distortion_matches_opencv_projectpoints_and_inverts_exactly():
    cam = Camera.webcam()
    rng = np.random.default_rng(3)
    p = np.c_[rng.uniform(-0.6, 0.6, (200, 2)), np.ones(200)] * rng.uniform(0.4, 2.0, (200, 1))
    ours = cam.project(p)
    theirs = cv2.projectPoints(p[:, None, :], np.zeros(3), np.zeros(3), cam.K, cam.D)[0].reshape(-1, 2)
    assert np.abs(ours - theirs).max() < 1e-9
    back = cam.project(cam.rays(ours))
    assert np.abs(back - ours).max() < 1e-6


def test_outline_conic_contains_the_tangent_rays_and_is_an_ellipse_not_centred_on_the_centre():
    C = np.array([0.3, -0.1, 0.5])  # 8 cm ball at 0.59 m, 31° off the axis
    Q = geom.image_conic(C, 0.04)
    pts = geom.outline_points(C, 0.04)
    m = np.c_[pts, np.ones(len(pts))]
    assert np.abs(np.einsum("ij,jk,ik->i", m, Q, m)).max() < 1e-12
    # the ellipse's centre (the midpoint of its points) is further out than the projected centre
    centre_of_points = 0.5 * (pts.max(0) + pts.min(0))
    ell = geom.ellipse_center(C, 0.04)
    proj = C[:2] / C[2]
    assert np.linalg.norm(ell - proj) > 0.003  # > 1.6 px at f = 554
    assert np.linalg.norm(ell - centre_of_points) < 2e-4
    assert np.linalg.norm(ell) > np.linalg.norm(proj)
    # along the radial axis the outline runs from tan(β − α) to tan(β + α)
    beta = np.arccos(C[2] / np.linalg.norm(C))
    alpha = np.arcsin(0.04 / np.linalg.norm(C))
    radial = pts @ (proj / np.linalg.norm(proj))
    assert radial.max() == pytest.approx(np.tan(beta + alpha), rel=1e-4)
    assert radial.min() == pytest.approx(np.tan(beta - alpha), rel=1e-4)
    assert np.linalg.norm(ell) == pytest.approx(0.5 * (np.tan(beta + alpha) + np.tan(beta - alpha)), rel=1e-9)


def test_sphere_from_its_outline_by_cone_and_by_conic():
    rng = np.random.default_rng(5)
    for _ in range(20):
        C = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.4, 0.4), rng.uniform(0.4, 2.0)])
        pts = geom.outline_points(C, 0.04, 50)
        u = np.c_[pts, np.ones(len(pts))]
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        c, a = geom.circle_from_rays(u)
        assert np.allclose(geom.sphere_from_cone(c, a, 0.04), C, atol=1e-9)
        assert np.allclose(geom.sphere_from_conic(-3.7 * geom.image_conic(C, 0.04), 0.04), C, atol=1e-9)


def test_ransac_ignores_the_edge_of_a_hand_over_a_third_of_the_ball():
    C = np.array([0.1, 0.05, 1.0])
    pts = geom.outline_points(C, 0.04, 90)
    ctr = 0.5 * (pts.max(0) + pts.min(0))
    rel = pts - ctr
    r = np.linalg.norm(rel, axis=1)
    d = rel / r[:, None]
    chord = 0.3 * r.mean()  # the hand's straight edge, 0.3 r from the centre on the +x side
    hidden = d[:, 0] > 0.3
    moved = hidden & (r - chord / np.maximum(d[:, 0], 1e-9) > 1.5 / 554)  # more than 1.5 px inside
    pts[hidden] = ctr + d[hidden] * (chord / d[hidden, 0])[:, None]  # the ray stops at the hand
    u = np.c_[pts, np.ones(len(pts))]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    c, a, inl = geom.ransac_circle(u, 1.0 / 554)
    assert moved.sum() > 20
    assert inl[~hidden].all() and not inl[moved].any()
    assert np.allclose(geom.sphere_from_cone(c, a, 0.04), C, atol=1e-6)


def test_camera_file_round_trip_and_clear_errors(tmp_path):
    cam = Camera.webcam()
    cam.save(tmp_path / "c.json")
    assert Camera.load(tmp_path / "c.json") == cam
    with pytest.raises(CameraFileError, match="does not exist"):
        Camera.load(tmp_path / "none.json")
    (tmp_path / "bad.json").write_text("{\"fx\": 1}")
    with pytest.raises(CameraFileError, match="lacks"):
        Camera.load(tmp_path / "bad.json")
