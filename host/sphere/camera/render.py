"""The virtual camera: frames of the ball as a webcam sees them, with their host time stamps.

What is modelled, and why:

- Geometry: a pinhole camera with lens distortion (:class:`~sphere.camera.model.Camera`); every pixel's
  ray is the exact inverse of the distortion, so the ball's outline is the true perspective image of a
  sphere (an ellipse, not a circle, off the axis) bent by the lens. Coverage at the outline is
  anti-aliased from the ray's angular distance to the tangent cone.
- Shading: Lambert with a key light from above-front, ambient light and a small specular highlight;
  the shell's colour is a configurable hue.
- Exposure: each frame integrates the ball over its exposure time (sub-frames averaged: motion blur).
  Auto-exposure changes the gain in steps with a 0.3 s settling, and the exposure time with it
  (a darker scene → longer exposure → more blur).
- Noise: shot noise (∝ √signal) and read noise, 8-bit quantisation; optionally the JPEG coding of an
  MJPG webcam (4:2:0 chroma: the colour edges the detector uses are blurred and ring).
- Scene: a cluttered background with objects of the ball's hue at lower saturation, one of the same
  colour (not round), a hand passing in front of the ball (partly or wholly), and the ball leaving the
  field of view when the trajectory does.
- Time: frame k is exposed from t₀ + k/fps (+ jitter); it reaches the host a capture latency after
  the middle of its exposure (USB transfer and decoding, 35 ms + an exponential tail).
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from sphere.camera.marker import texture_lookup
from sphere.camera.model import Camera

BALL_RADIUS_M = 0.04  # the sphere is 8 cm across


def hue_rgb(hue_deg: float, s: float = 0.85, v: float = 0.9) -> np.ndarray:
    return np.array(colorsys.hsv_to_rgb((hue_deg % 360) / 360.0, s, v))


def look_at(cam_pos, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Rotation camera → world (columns: the camera's x right, y down, z forward in world coordinates)."""
    z = np.asarray(target, float) - np.asarray(cam_pos, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


@dataclass
class Occlusion:
    """A hand in front of the ball from t0 to t1: ``cover`` 1 hides it entirely, 0.3 hides about a third."""

    t0: float
    t1: float
    cover: float = 0.35
    side_deg: float = 200.0  # from which side the hand comes (image angle)


@dataclass
class Scene:
    camera: Camera
    R_wc: np.ndarray  # camera → world rotation
    cam_pos: np.ndarray  # camera position, world (m)
    hue_deg: float = 120.0
    radius_m: float = BALL_RADIUS_M
    fps: float = 30.0
    exposure_s: float = 0.008  # at gain 1
    latency_s: float = 0.035  # middle of exposure → arrival, without the tail
    latency_tail_s: float = 0.005  # mean of the exponential tail
    frame_jitter_s: float = 0.001
    occlusions: list = field(default_factory=list)
    gain_step_s: float = 2.5  # auto-exposure changes its gain about this often
    seed: int = 1
    read_noise: float = 2.0
    shot_noise: float = 0.6
    jpeg_quality: int | None = None  # the frame through JPEG (MJPG webcams: 4:2:0 chroma, blocks), or raw
    marker: object = None  # a MarkerSpec printed on the shell (sphere.camera.marker), or None
    body_rotation: object = None  # t ↦ 3×3 body → world rotation (needed with a marker)

    def __post_init__(self):
        self.R_wc = np.asarray(self.R_wc, float)
        self.cam_pos = np.asarray(self.cam_pos, float)
        rng = np.random.default_rng(self.seed)
        self._background = _background(self.camera.width, self.camera.height, self.hue_deg, rng)
        self._noise = rng.standard_normal((3, self.camera.height + 16, self.camera.width + 16, 3)).astype(np.float32)
        self._gain_levels = rng.uniform(0.65, 1.35, 64)
        self._gain_levels[0] = 1.0
        self._rng = rng
        self._albedo = hue_rgb(self.hue_deg).astype(np.float32)
        self._light = np.array([0.3, -0.8, -0.5]) / np.linalg.norm([0.3, -0.8, -0.5])  # towards the light, camera frame
        self._bitmap = self.marker.bitmap() if self.marker is not None else None

    def to_camera(self, p_world) -> np.ndarray:
        return (np.asarray(p_world, float) - self.cam_pos) @ self.R_wc

    def gain(self, t: float) -> float:
        """Auto-exposure gain: steps every gain_step_s, each settling with a 0.3 s time constant."""
        k = int(t // self.gain_step_s)
        a, b = self._gain_levels[k % 64 - 1] if k else 1.0, self._gain_levels[k % 64]
        return float(b + (a - b) * np.exp(-(t - k * self.gain_step_s) / 0.3))

    # -- time ---------------------------------------------------------------------------------------------
    def frame_times(self, t_start: float, t_end: float):
        """(exposure start, exposure middle, host arrival) for every frame in [t_start, t_end)."""
        rng = np.random.default_rng(self.seed + 7)
        n = int(np.floor((t_end - t_start) * self.fps))
        start = t_start + np.arange(n) / self.fps + rng.normal(0.0, self.frame_jitter_s, n)
        exp = np.array([self.exposure_s * self.gain(t) for t in start])
        mid = start + exp / 2
        arrival = mid + self.latency_s + rng.exponential(self.latency_tail_s, n)
        return start, mid, arrival, exp

    # -- one frame ----------------------------------------------------------------------------------------
    def render(self, t_start: float, exposure_s: float, ball_world, frame_index: int = 0) -> np.ndarray:
        """BGR uint8 frame exposed from t_start for exposure_s; ``ball_world(t)`` gives the centre (world)."""
        cam = self.camera
        g = self.gain(t_start)
        img = self._background.copy()
        subs = [t_start + exposure_s * (i + 0.5) / 4 for i in range(4)]
        centres = [self.to_camera(ball_world(t)) for t in subs]
        roi = self._ball_roi(centres)
        if roi is not None:
            y0, y1, x0, x1 = roi
            rays = cam.ray_map[y0:y1, x0:x1]
            acc = np.zeros(rays.shape, np.float32)
            for t, C in zip(subs, centres):
                R_cb = None
                if self.marker is not None and self.body_rotation is not None:
                    R_cb = self.R_wc.T @ self.body_rotation(t)
                acc += self._ball_layer(rays, C, img[y0:y1, x0:x1], R_cb)
            img[y0:y1, x0:x1] = acc / len(centres)
        for occ in self.occlusions:
            if occ.t0 <= t_start < occ.t1:
                self._hand(img, occ, centres[len(centres) // 2], t_start)
        img *= g
        # noise: shot (∝ √signal) and read noise, from a bank of noise frames shifted at random
        k = frame_index % 3
        oy, ox = self._rng.integers(0, 16, 2)
        n = self._noise[k, oy:oy + cam.height, ox:ox + cam.width]
        img += n * (self.read_noise + self.shot_noise * np.sqrt(np.maximum(img, 0.0)))
        np.clip(img, 0, 255, out=img)
        out = img[..., ::-1].astype(np.uint8)  # RGB → BGR (OpenCV's order)
        if self.jpeg_quality:
            import cv2  # optional dependency: the camera extra (OpenCV)

            ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(self.jpeg_quality)])
            out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        return out

    def _ball_roi(self, centres):
        cam = self.camera
        boxes = []
        for C in centres:
            D = np.linalg.norm(C)
            if C[2] <= self.radius_m * 1.5:
                continue
            c = C / D
            a = np.arcsin(min(self.radius_m / D, 0.999))
            # the outline: sample the cone and project (distortion included)
            e1 = np.cross(c, [0.0, 1.0, 0.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(c, e1)
            phi = np.linspace(0, 2 * np.pi, 16, endpoint=False)
            u = np.cos(a) * c + np.sin(a) * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
            px = cam.project(u)
            boxes.append((px.min(0), px.max(0)))
        if not boxes:
            return None
        lo = np.min([b[0] for b in boxes], axis=0) - 3
        hi = np.max([b[1] for b in boxes], axis=0) + 4
        x0, y0 = np.maximum(np.floor(lo).astype(int), 0)
        x1, y1 = np.minimum(np.ceil(hi).astype(int), [cam.width, cam.height])
        if x1 <= x0 or y1 <= y0:
            return None
        return y0, y1, x0, x1

    def _ball_layer(self, rays, C, under, R_cb=None):
        D = float(np.linalg.norm(C))
        R = self.radius_m
        c = C / D
        sa = R / D
        ca = np.sqrt(1 - sa * sa)
        dot = rays @ c.astype(np.float32)
        pix = 1.0 / self.camera.fx
        cov = np.clip(0.5 + (dot - ca) / (sa * pix), 0.0, 1.0)[..., None]
        # shading from the surface normal where the ray meets the sphere (the rim: the tangent point)
        uc = dot * D
        t = uc - np.sqrt(np.maximum(uc * uc - (D * D - R * R), 0.0))
        hit = t[..., None] * rays
        nrm = (hit - C.astype(np.float32)) / R
        lam = np.clip(nrm @ self._light.astype(np.float32), 0.0, 1.0)
        half = self._light + np.array([0.0, 0.0, -1.0])
        half /= np.linalg.norm(half)
        spec = np.clip(nrm @ half.astype(np.float32), 0.0, 1.0) ** 40
        albedo = np.broadcast_to(self._albedo, nrm.shape)
        if R_cb is not None:
            R_cm = (R_cb @ self.marker.mount).astype(np.float32)  # marker → camera
            on, grey = texture_lookup(self.marker, self._bitmap, nrm @ R_cm, R)
            albedo = np.where(on[..., None], (0.06 + 0.84 * grey)[..., None] * np.ones(3, np.float32), albedo)
        col = (0.3 + 0.7 * lam)[..., None] * albedo * 255.0 + (60.0 * spec)[..., None]
        return under * (1 - cov) + col * cov

    def _hand(self, img, occ: Occlusion, C, t):
        """A skin-coloured hand (palm and four fingers) 10 cm in front of the ball."""
        import cv2  # optional dependency: the camera extra (OpenCV)

        cam = self.camera
        if C[2] <= 0.2:
            return
        ctr = cam.project(C)
        D = np.linalg.norm(C)
        r_ball = cam.fx * self.radius_m / D
        scale = cam.fx / max(D - 0.1, 0.15)
        palm = (0.045 * scale, 0.055 * scale)
        ang = np.radians(occ.side_deg + 20.0 * np.sin(2 * t))
        d = np.array([np.cos(ang), np.sin(ang)])
        # the palm's edge sits at (1 − 2·cover)·r from the ball's centre, on the hand's side
        edge = (1.0 - 2.0 * occ.cover) * r_ball
        centre = ctr + d * (edge + palm[0]) if occ.cover < 1 else ctr
        mask = np.zeros(img.shape[:2], np.uint8)
        sh = 4  # fixed-point bits: sub-pixel drawing
        p = lambda v: (int(round(v[0] * 16)), int(round(v[1] * 16)))  # noqa: E731
        cv2.ellipse(mask, p(centre), (int(palm[0] * 16), int(palm[1] * 16)), float(np.degrees(ang)), 0, 360, 255,
                    -1, cv2.LINE_AA, sh)
        for i, off in enumerate((-0.03, -0.01, 0.01, 0.03)):
            perp = np.array([-d[1], d[0]])
            base = centre + perp * off * scale
            tip = base + d * (0.07 + 0.01 * (i % 2)) * scale
            cv2.line(mask, p(base), p(tip), 255, max(1, int(0.017 * scale)), cv2.LINE_AA, sh)
        a = (mask.astype(np.float32) / 255.0)[..., None]
        skin = np.array([205.0, 150.0, 120.0], np.float32)
        shade = 0.85 + 0.15 * np.sin(np.arange(img.shape[1], dtype=np.float32) / 23.0)[None, :, None]
        img *= 1 - a
        img += a * skin * shade


def _background(w: int, h: int, hue_deg: float, rng) -> np.ndarray:
    """A cluttered desk scene (RGB float32): wall gradient, desk, books and boxes, things of the ball's hue
    at lower saturation, and one object of exactly the ball's colour that is not round."""
    import cv2  # optional dependency: the camera extra (OpenCV)

    img = np.zeros((h, w, 3), np.float32)
    yy = np.linspace(0, 1, h, dtype=np.float32)[:, None, None]
    img[:] = (1 - yy) * np.array([190, 185, 175], np.float32) + yy * np.array([120, 110, 100], np.float32)
    img[int(h * 0.7):] = np.array([140, 105, 75], np.float32)  # desk
    for _ in range(28):
        x, y = rng.integers(0, w), rng.integers(0, h)
        bw, bh = rng.integers(15, 110), rng.integers(15, 110)
        if rng.random() < 0.35:  # the ball's hue, washed out or dark (plants, a cushion ...)
            col = hue_rgb(hue_deg + rng.uniform(-20, 20), rng.uniform(0.15, 0.4), rng.uniform(0.3, 0.8))
        else:
            col = hue_rgb(rng.uniform(0, 360), rng.uniform(0.1, 0.8), rng.uniform(0.2, 0.95))
        col = (col * 255).astype(float).tolist()
        if rng.random() < 0.5:
            cv2.rectangle(img, (int(x), int(y)), (int(x + bw), int(y + bh)), col, -1)
        else:
            cv2.ellipse(img, (int(x), int(y)), (int(bw // 2), int(bh // 3)), float(rng.uniform(0, 180)), 0, 360, col, -1)
    # an object of the ball's own colour: a mug-shaped box near a corner
    col = (hue_rgb(hue_deg) * 255 * 0.8).tolist()
    cv2.rectangle(img, (int(w * 0.04), int(h * 0.72)), (int(w * 0.04) + 30, int(h * 0.72) + 42), col, -1)
    img = cv2.GaussianBlur(img, (0, 0), 0.8)
    return img


@lru_cache(maxsize=2)
def _fine_rays(camera: Camera, k: int = 3) -> np.ndarray:
    """Unit rays of a k×k grid inside every pixel, (h·k, w·k, 3) float32, for anti-aliased board images."""
    h, w = camera.height, camera.width
    v, u = np.mgrid[0:h * k, 0:w * k].astype(float)
    px = np.stack([(u.ravel() + 0.5) / k - 0.5, (v.ravel() + 0.5) / k - 0.5], 1)
    return camera.rays(px).reshape(h * k, w * k, 3).astype(np.float32)


def chessboard_texture(cols: int, rows: int, px_per_square: int = 20) -> np.ndarray:
    """A printed chessboard, cols × rows squares, the top-left one black (grey levels 0-255)."""
    j, i = np.mgrid[0:rows * px_per_square, 0:cols * px_per_square] // px_per_square
    return np.where((i + j) % 2 == 0, 25, 235).astype(np.uint8)


def render_board(camera: Camera, R_cb: np.ndarray, t_cb: np.ndarray, cols: int, rows: int, square_m: float,
                 noise: float = 2.0, seed: int = 0, texture: np.ndarray | None = None) -> np.ndarray:
    """A printed board seen by ``camera``: board point X_b (z = 0 plane; x right, y down from the board's
    top-left corner) is at R_cb X_b + t_cb in the camera frame. The board is ``texture`` (default a
    chessboard of cols × rows squares) over cols × rows squares, on white paper one square wider all round,
    in front of a dark background. Grey uint8, 3×3 supersampled."""
    h, w = camera.height, camera.width
    tex = chessboard_texture(cols, rows) if texture is None else np.asarray(texture)
    rays = _fine_rays(camera).reshape(-1, 3)
    R_cb = np.asarray(R_cb, np.float32)
    t_cb = np.asarray(t_cb, np.float32)
    n_cb = R_cb[:, 2]
    s = (n_cb @ t_cb) / (rays @ n_cb)
    pts = (rays * s[:, None] - t_cb) @ R_cb  # board coordinates
    u = pts[:, 0] / (cols * square_m)  # 0…1 across the printed area
    v = pts[:, 1] / (rows * square_m)
    inside = (u >= 0) & (u < 1) & (v >= 0) & (v < 1) & (s > 0)
    paper = (pts[:, 0] >= -square_m) & (pts[:, 0] < (cols + 1) * square_m) & (pts[:, 1] >= -square_m) \
        & (pts[:, 1] < (rows + 1) * square_m) & (s > 0)
    val = np.where(paper, 235.0, 60.0).astype(np.float32)
    th, tw = tex.shape[:2]
    ti = np.clip((v[inside] * th).astype(int), 0, th - 1)
    tj = np.clip((u[inside] * tw).astype(int), 0, tw - 1)
    val[inside] = tex[ti, tj]
    img = val.reshape(h, 3, w, 3).mean(axis=(1, 3))
    img += np.random.default_rng(seed).normal(0, noise, (h, w)).astype(np.float32)
    return np.clip(img, 0, 255).astype(np.uint8)
