"""A printed ArUco marker on the shell: the ball's absolute orientation (heading included, no magnetometer)
whenever the camera sees it.

The marker (OpenCV's DICT_4X4_50, id 7 by default; 6×6 cells with its black border, printed with a white
quiet zone of one cell) is wrapped onto the sphere by the gnomonic projection from the tangent plane at
the body's +z axis: plane point (x, y, R) ↦ R·(x, y, R)/|(x, y, R)|. That keeps its corners on one plane
(they are symmetric about +z). A 2-3 cm marker's own PnP pose is poor (a corner off by 1 px turns it by
several degrees, and IPPE's two solutions are close); the ball's centre, from its outline, is known to
a millimetre. So each corner's ray is met with the sphere, and the rotation that takes the corners'
body-frame vectors (from the centre) to those points is solved by Kabsch.

Body frame: the marker's image right is body +x, its image down body −y, seen from outside (+z).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DICTIONARY = 0  # cv2.aruco.DICT_4X4_50


@dataclass(frozen=True)
class MarkerSpec:
    id: int = 7
    side_m: float = 0.035  # the black square, flat, before it is wrapped onto the shell
    face: str = "+z"  # the body axis (sensor frame) the marker's centre sits on: ±x, ±y or ±z

    @property
    def mount(self) -> np.ndarray:
        """Marker frame → body frame: the marker's +z on ``face``."""
        axis = {"x": 0, "y": 1, "z": 2}[self.face[1]]
        sign = -1.0 if self.face[0] == "-" else 1.0
        z = np.zeros(3)
        z[axis] = sign
        x = np.zeros(3)
        x[(axis + 1) % 3] = 1.0
        y = np.cross(z, x)
        return np.stack([x, y, z], axis=1)

    def bitmap(self) -> np.ndarray:
        """8×8 cells: the 6×6 marker in a one-cell white quiet zone (0 black, 1 white)."""
        import cv2  # optional dependency: the camera extra (OpenCV)

        m = cv2.aruco.generateImageMarker(cv2.aruco.getPredefinedDictionary(DICTIONARY), self.id, 6)
        out = np.ones((8, 8), np.float32)
        out[1:7, 1:7] = (m > 127).astype(np.float32)
        return out

    def corners_body(self, radius_m: float) -> np.ndarray:
        """The marker's four corners on the sphere (body frame), in ArUco's order: top-left, top-right,
        bottom-right, bottom-left."""
        h = self.side_m / 2
        plane = np.array([[-h, h, radius_m], [h, h, radius_m], [h, -h, radius_m], [-h, -h, radius_m]])
        return radius_m * plane / np.linalg.norm(plane, axis=1, keepdims=True)


def texture_lookup(spec: MarkerSpec, bitmap: np.ndarray, n_body: np.ndarray, radius_m: float):
    """For unit normals in the body frame (…, 3): (mask, value) — where the printed square (with its quiet
    zone) is, and its grey level there (0 black … 1 white)."""
    z = n_body[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = n_body[..., 0] / z * radius_m
        y = -n_body[..., 1] / z * radius_m
    cell = spec.side_m / 6
    u = (x + 4 * cell) / cell  # 0…8 across the bitmap with its quiet zone
    v = (y + 4 * cell) / cell
    mask = (z > 0.2) & (u >= 0) & (u < 8) & (v >= 0) & (v < 8)
    ui = np.clip(np.where(mask, u, 0).astype(int), 0, 7)
    vi = np.clip(np.where(mask, v, 0).astype(int), 0, 7)
    return mask, bitmap[vi, ui]


@dataclass
class MarkerPose:
    R_cam_body: np.ndarray  # body → camera rotation
    center_cam: np.ndarray  # the ball's centre that this pose implies (camera frame)
    corners_px: np.ndarray
    reprojection_px: float


class MarkerDetector:
    def __init__(self, camera, spec: MarkerSpec = MarkerSpec(), radius_m: float = 0.04):
        import cv2  # optional dependency: the camera extra (OpenCV)

        self.camera = camera
        self.spec = spec
        self.radius_m = radius_m
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_CONTOUR
        params.minMarkerPerimeterRate = 0.01
        params.polygonalApproxAccuracyRate = 0.06  # the wrapped marker's edges are slightly curved
        self._det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(DICTIONARY), params)
        self._obj = spec.corners_body(radius_m)
        self._plane_h = float(self._obj[0, 2])

    def detect(self, bgr: np.ndarray, center_px, radius_px: float, center_cam=None) -> MarkerPose | None:
        """The marker on the ball whose outline is at (center_px, radius_px); None when it is not seen."""
        import cv2  # optional dependency: the camera extra (OpenCV)

        H, W = bgr.shape[:2]
        m = radius_px * 1.2 + 4
        x0, x1 = int(max(0, center_px[0] - m)), int(min(W, center_px[0] + m + 1))
        y0, y1 = int(max(0, center_px[1] - m)), int(min(H, center_px[1] + m + 1))
        if x1 - x0 < 12 or y1 - y0 < 12:
            return None
        roi = cv2.cvtColor(bgr[y0:y1, x0:x1], cv2.COLOR_BGR2GRAY)
        scale = 1
        if radius_px < 40:  # small in the image: detect on an upsampled window
            scale = 2
            roi = cv2.resize(roi, None, fx=2, fy=2, interpolation=cv2.INTER_CUBIC)
        corners, ids, _ = self._det.detectMarkers(roi)
        if ids is None:
            return None
        hit = [i for i, v in enumerate(ids.ravel()) if v == self.spec.id]
        if not hit:
            return None
        c = corners[hit[0]].reshape(4, 2) / scale + [x0 + (scale - 1) / (2 * scale), y0 + (scale - 1) / (2 * scale)]
        if center_cam is None:
            return None
        return self.pose_on_sphere(c, np.asarray(center_cam, float))

    def pose_on_sphere(self, corners_px: np.ndarray, center_cam: np.ndarray) -> MarkerPose | None:
        """The body's rotation from the corners' rays where they meet the sphere (its centre from the
        outline, which is far better known than a 2-cm marker's own pose): the four corner vectors from the
        centre, body frame ↔ camera frame, by Kabsch."""
        u = self.camera.rays(corners_px)
        b = u @ center_cam
        disc = b * b - (center_cam @ center_cam - self.radius_m ** 2)
        if np.any(disc < 0):  # a corner's ray misses the sphere: the corners do not belong to this ball
            return None
        pts = u * (b - np.sqrt(disc))[:, None]  # the near intersections
        A = self._obj  # marker frame, from the centre
        B = pts - center_cam
        U, _, Vt = np.linalg.svd(A.T @ B)
        d = np.sign(np.linalg.det(Vt.T @ U.T))
        R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T  # marker → camera
        res = B - A @ R.T
        R = R @ self.spec.mount.T  # body → camera
        err_px = float(np.sqrt(np.mean(np.sum(res * res, axis=1)))) * self.camera.fx / float(np.linalg.norm(center_cam))
        return MarkerPose(R, center_cam.copy(), corners_px, err_px)
