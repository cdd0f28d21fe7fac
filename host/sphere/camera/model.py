"""A pinhole camera with OpenCV's lens distortion model (k1, k2, p1, p2, k3), and its JSON file.

Camera frame: x right, y down, z along the optical axis (OpenCV's convention). Normalised image
coordinates are (x/z, y/z) before distortion.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from sphere.errors import SphereError


class CameraFileError(SphereError, ValueError):
    """A camera file that cannot be used (one line saying what is wrong)."""


@dataclass(frozen=True)
class Camera:
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple = (0.0, 0.0, 0.0, 0.0, 0.0)  # k1, k2, p1, p2, k3
    rms_px: float | None = field(default=None, compare=False)  # reprojection RMS when calibrated

    @classmethod
    def webcam(cls, width: int = 640, height: int = 480, hfov_deg: float = 60.0,
               dist=(-0.12, 0.05, 0.0005, -0.0003, 0.0)) -> "Camera":
        """A typical USB webcam: 60° horizontal field of view, mild barrel distortion."""
        f = 0.5 * width / np.tan(np.radians(hfov_deg) / 2)
        return cls(width, height, f, f, width / 2 - 0.5 + 1.3, height / 2 - 0.5 - 0.8, tuple(dist))

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def D(self) -> np.ndarray:
        return np.asarray(self.dist, float)

    def distort(self, xn: np.ndarray) -> np.ndarray:
        """Normalised coordinates (N, 2) → pixel coordinates (N, 2)."""
        xn = np.asarray(xn, float)
        x, y = xn[..., 0], xn[..., 1]
        k1, k2, p1, p2, k3 = self.dist
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=-1)

    def project(self, p_cam: np.ndarray) -> np.ndarray:
        """Points in the camera frame (N, 3) → pixels (N, 2)."""
        p = np.asarray(p_cam, float)
        return self.distort(p[..., :2] / p[..., 2:3])

    def undistort(self, px: np.ndarray, iterations: int = 30) -> np.ndarray:
        """Pixels (N, 2) → normalised coordinates (N, 2): the distortion inverted by fixed-point iteration
        (as OpenCV's undistortPoints does), run until the round trip is exact to ~1e-9 px for webcam lenses."""
        px = np.asarray(px, np.float64).reshape(-1, 2)
        xd = (px[:, 0] - self.cx) / self.fx
        yd = (px[:, 1] - self.cy) / self.fy
        k1, k2, p1, p2, k3 = self.dist
        x, y = xd.copy(), yd.copy()
        for _ in range(iterations):
            r2 = x * x + y * y
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
            dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
            x = (xd - dx) / radial
            y = (yd - dy) / radial
        return np.stack([x, y], axis=1)

    def rays(self, px: np.ndarray, iterations: int = 30) -> np.ndarray:
        """Pixels (N, 2) → unit rays (N, 3) in the camera frame."""
        xn = self.undistort(px, iterations)
        r = np.concatenate([xn, np.ones((len(xn), 1))], axis=1)
        return r / np.linalg.norm(r, axis=1, keepdims=True)

    def rays_interpolated(self, px: np.ndarray) -> np.ndarray:
        """Unit rays of pixels (N, 2) interpolated from :attr:`ray_map` (bilinear, then normalised): one
        OpenCV call instead of the iterative inverse; the rays differ from :meth:`rays` by < 1e-6 rad."""
        import cv2  # optional dependency: the camera extra (OpenCV)

        px = np.asarray(px, np.float32).reshape(1, -1, 2)
        r = cv2.remap(self.ray_map, px[..., 0], px[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        r = r.reshape(-1, 3).astype(np.float64)
        inside = (px[0, :, 0] >= 0) & (px[0, :, 0] <= self.width - 1) & (px[0, :, 1] >= 0) & (px[0, :, 1] <= self.height - 1)
        if not inside.all():
            r[~inside] = self.rays(px[0, ~inside].astype(np.float64))
        return r / np.linalg.norm(r, axis=1, keepdims=True)

    @cached_property
    def ray_map(self) -> np.ndarray:
        """Unit ray of every pixel centre, (height, width, 3) float32 (computed once per camera)."""
        v, u = np.mgrid[0:self.height, 0:self.width]
        px = np.stack([u.ravel(), v.ravel()], axis=1).astype(float)
        return self.rays(px).reshape(self.height, self.width, 3).astype(np.float32)

    # -- file --------------------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        d = asdict(self)
        d["dist"] = list(self.dist)
        return d

    def save(self, path: Path | str) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load(cls, path: Path | str) -> "Camera":
        path = Path(path)
        try:
            d = json.loads(path.read_text())
        except FileNotFoundError:
            raise CameraFileError(f"{path} does not exist; make one with `sphere camera calibrate`") from None
        except (OSError, ValueError) as e:
            raise CameraFileError(f"{path} is not a camera file (JSON from `sphere camera calibrate`): {e}") from None
        need = ("width", "height", "fx", "fy", "cx", "cy")
        missing = [k for k in need if k not in d]
        if not isinstance(d, dict) or missing:
            raise CameraFileError(f"{path} lacks {', '.join(missing) or 'its fields'}; "
                                  f"re-run `sphere camera calibrate`")
        dist = tuple(float(v) for v in d.get("dist", (0, 0, 0, 0, 0)))
        if len(dist) != 5:
            raise CameraFileError(f"{path}: dist must have 5 values (k1, k2, p1, p2, k3), not {len(dist)}")
        return cls(int(d["width"]), int(d["height"]), float(d["fx"]), float(d["fy"]), float(d["cx"]),
                   float(d["cy"]), dist, d.get("rms_px"))
