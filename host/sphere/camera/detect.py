"""The ball in a camera frame: found by colour, its outline fitted robustly, its centre in 3-D.

1. **Colour**: each pixel's chroma (a = R − (G+B)/2, b = √3/2 (G − B), the hue circle's plane) is
   projected on the ball's hue direction. The projection is *linear* in RGB, so a pixel half covered by
   the ball (anti-aliasing, motion blur) has the mean of the two values: the outline is where a profile
   crosses halfway between the ball's level and the background's. The mask of candidates asks for a
   saturated colour near the hue (projection ≥ 45 % of the pixel's brightness, little chroma across).
2. **Candidates**: connected regions of the mask (at half resolution when searching the whole frame, in a
   window around the last position when tracking); the deepest point of each region's distance
   transform is a centre that a hand over part of the ball does not drag off, and its depth a radius.
3. **Outline**: 96 rays from that centre; on each the sub-pixel 50 % crossing of the hue projection.
   Rays stopped by a hand, a same-coloured object behind or the image border give points off the
   circle, or none.
4. **Fit**: the points' unit rays (lens distortion undone) lie on a small circle of the unit sphere
   (see :mod:`sphere.camera.sphere_geometry`): RANSAC on triples, least squares on the inliers, then a
   second pass of rays from the fitted centre. The centre's covariance comes from the fit's residuals
   and the arc the inliers cover (a half-hidden ball is less certain, in the direction it is hidden).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sphere.camera import sphere_geometry as geom
from sphere.camera.model import Camera

N_RAYS = 96
#: Without a track, a region counts as the ball only when most of a round outline is seen, and sharply:
#: the rest (a ball half hidden, half out of the frame, or a same-coloured thing behind it) waits for the
#: tracker's hint.
COLD_START_INLIERS = 0.6
#: Tracking: an outline counts when this share of the rays that found an edge agree on one circle (a
#: hand over a third of the ball leaves ~0.65-0.8; a box or a blob of the ball's colour ~0.4-0.5).
TRACK_INLIERS = 0.6
COLD_START_RESIDUAL_PX = 0.4
#: ... or, when the fit's own residual says the outline is a sharp circle, from fewer points: a ball partly
#: behind a hand at the start (half of its outline hidden leaves 47-55 of 96 rays, fitting to 0.11-0.15 px;
#: a same-coloured thing in the clutter fits 37-50 rays to 0.44-0.68 px)
PARTIAL_INLIERS = 0.45
PARTIAL_RESIDUAL_PX = 0.25


@dataclass
class Detection:
    center_cam: np.ndarray  # (3,) metres, camera frame
    cov: np.ndarray  # (3, 3) m², camera frame
    center_px: np.ndarray  # (2,) where the centre projects
    radius_px: float  # outline radius, pixels (mean)
    inliers: int
    rays: int
    residual_px: float
    candidates: int = 1
    colour: np.ndarray | None = None  # unit RGB direction of the ball's colour in this frame

    @property
    def distance_m(self) -> float:
        return float(np.linalg.norm(self.center_cam))


def hue_projection(bgr: np.ndarray, hue_deg: float):
    """(along, across, brightness) float32 images: chroma along the hue direction, across it, max(R,G,B)."""
    f = bgr.astype(np.float32)
    b, g, r = f[..., 0], f[..., 1], f[..., 2]
    ca = r - 0.5 * (g + b)
    cb = 0.8660254 * (g - b)
    h = np.radians(hue_deg)
    along = ca * np.float32(np.cos(h)) + cb * np.float32(np.sin(h))
    across = cb * np.float32(np.cos(h)) - ca * np.float32(np.sin(h))
    return along, across, np.maximum(np.maximum(r, g), b)


def _row_median(x: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Median of each row of x (rays, samples[, channels]) over its valid samples (0 where none)."""
    big = np.float32(1e30)
    v = valid if x.ndim == 2 else valid[..., None]
    srt = np.sort(np.where(v, x, big), axis=1)
    m = valid.sum(axis=1)
    k = np.maximum((m - 1) // 2, 0)
    k2 = np.maximum(m // 2, 0)
    take = (lambda i: np.take_along_axis(srt, i[:, None], 1)[:, 0]) if x.ndim == 2 else \
        (lambda i: np.take_along_axis(srt, i[:, None, None], 1)[:, 0])
    out = 0.5 * (take(k) + take(k2))
    return np.where((m > 0) if x.ndim == 2 else (m > 0)[:, None], out, 0.0)


class BallDetector:
    def __init__(self, camera: Camera, hue_deg: float = 120.0, radius_m: float = 0.04, n_rays: int = N_RAYS,
                 min_radius_px: float = 3.0, inlier_px: float = 1.0, seed: int = 0, colour_tol_deg: float = 6.0):
        self.camera = camera
        self.hue_deg = hue_deg
        self.radius_m = radius_m
        self.n_rays = n_rays
        self.min_radius_px = min_radius_px
        #: the ball's own colour (unit RGB direction), learnt from the first clear view (a cold start);
        #: later outlines must be of that colour within colour_tol_deg (shading and exposure scale it, they
        #: do not turn it), so a round thing of a similar hue behind is not taken for the ball
        self.colour = None
        self.colour_tol_deg = colour_tol_deg
        self._last_colour = None
        self.inlier_px = inlier_px
        self._rng = np.random.default_rng(seed)
        self._dirs_by_n = {}
        for k in (n_rays // 2, n_rays):
            phi = np.linspace(0, 2 * np.pi, k, endpoint=False)
            self._dirs_by_n[k] = np.stack([np.cos(phi), np.sin(phi)], 1)
        self._dirs = self._dirs_by_n[n_rays]

    # -- candidates --------------------------------------------------------------------------------------
    def _candidates(self, bgr, x0, y0, scale):
        import cv2  # optional dependency: the camera extra (OpenCV)

        along, across, bright = hue_projection(bgr, self.hue_deg)
        mask = ((along > 0.45 * bright) & (np.abs(across) < 0.35 * along) & (bright > 30)).astype(np.uint8)
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
        # holes filled (a marker, a highlight on the ball): each region's outer contour, filled
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(mask, contours, -1, 1, -1)
        n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        if n <= 1:
            return []
        dist = cv2.distanceTransform(mask, cv2.DIST_L2, 5)
        out = []
        for i in range(1, n):
            area = stats[i, cv2.CC_STAT_AREA]
            if area * scale * scale < np.pi * self.min_radius_px ** 2:
                continue
            x, y, w, h = stats[i, :4]
            sub = np.where(labels[y:y + h, x:x + w] == i, dist[y:y + h, x:x + w], 0.0)
            _, d, _, (px, py) = cv2.minMaxLoc(sub)
            r_in = (float(d) + 0.5) * scale
            r_area = np.sqrt(area / np.pi) * scale
            if r_in < self.min_radius_px * 0.6:
                continue
            roundness = min(1.0, (r_in / max(r_area, 1e-9)) ** 2)  # 1 for a disc, lower when elongated
            # the radius the rays search over: the area's (a ball partly hidden is a clipped disc whose inscribed
            # circle is far smaller than the ball and off its centre)
            out.append((np.array([x0 + (x + px + 0.5) * scale - 0.5, y0 + (y + py + 0.5) * scale - 0.5]),
                        max(r_in, r_area), roundness))
        return out

    # -- outline -----------------------------------------------------------------------------------------
    def _edge_points(self, rgb, centre, r0, offset, n_rays=None, span=(0.35, 1.9)):
        """Sub-pixel outline points on rays from ``centre`` (image px); ``rgb`` (float32) covers the window
        at ``offset`` (x0, y0).

        Each sample is unmixed: p = x·b̂ + y·g, with b̂ the ball's colour direction (median of the inner
        samples, normalised: shading scales it, the hue does not change) and g the ray's background
        (median of its outer samples). The ball's coverage is 1 − y whatever the shading, so the outline
        is where it crosses ½. Where the background is dark or of the ball's own colour the unmixing is
        ill-posed; there the hue projection's crossing halfway between the levels 2-6 px either side is
        used instead."""
        import cv2  # optional dependency: the camera extra (OpenCV)

        dirs = self._dirs_by_n[n_rays or self.n_rays]
        nr = len(dirs)
        step = 0.5
        s = np.arange(span[0] * r0, span[1] * r0 + 6.0, step, dtype=np.float32)
        pts = centre[None, None, :] + s[None, :, None] * dirs[:, None, :]  # (rays, samples, 2)
        mx = (pts[..., 0] - offset[0]).astype(np.float32)
        my = (pts[..., 1] - offset[1]).astype(np.float32)
        h, w = rgb.shape[:2]
        inside = (mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)
        prof = cv2.remap(rgb, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)  # (rays, n, 3)
        n = len(s)
        rows = np.arange(nr)
        inner = s <= max(0.7, span[0] + 0.15) * r0
        outer = s >= min(1.35, span[1] - 0.15) * r0 + 2.0
        ok = inside[:, inner].all(axis=1) & (inside[:, outer].sum(axis=1) >= 3)
        if not ok.any():
            return np.zeros((0, 2))
        # the ball's colour: the inner samples of its hue (not a marker, a highlight or a hand over it)
        inner_rgb = prof[ok][:, inner].reshape(-1, 3)
        a_i, c_i, b_i = hue_projection(inner_rgb[None, :, ::-1], self.hue_deg)
        hue_ok = ((a_i > 0.45 * b_i) & (np.abs(c_i) < 0.35 * a_i) & (b_i > 30))[0]
        if hue_ok.sum() < max(8, 0.3 * len(inner_rgb)):
            return np.zeros((0, 2))  # what the rays start in is mostly not the ball's colour
        ball = np.median(inner_rgb[hue_ok], axis=0)
        bhat = ball / max(float(np.linalg.norm(ball)), 1e-6)
        self._last_colour = bhat
        if self.colour is not None and float(bhat @ self.colour) < np.cos(np.radians(self.colour_tol_deg)):
            return np.zeros((0, 2))  # a thing of a similar hue, not the ball's own colour
        g = _row_median(prof[:, outer], inside[:, outer])  # (rays, 3)
        gg = np.einsum("ij,ij->i", g, g)
        bg = g @ bhat
        det = gg - bg * bg  # |g|² sin²(angle between g and b̂)
        unmix = ok & (gg > 30.0 ** 2) & (det > 0.08 * gg)
        pb = prof @ bhat
        pg = np.einsum("ijk,ik->ij", prof, g)
        with np.errstate(all="ignore"):
            cover = 1.0 - (pg - bg[:, None] * pb) / np.where(unmix, det, 1.0)[:, None]
        val = cover
        use = unmix.copy()
        # a dark thing right behind the ball's edge (a box, a shadow) with a lighter background further out unmixes
        # against the wrong background: its pixels count as ball and the crossing lands on the far side of it
        # (6-10 px out in front of a dark box). The pixels just inside an unmixed crossing must be of the ball's
        # colour; where they are not, the ray is measured by the hue projection's local levels instead
        search = s > 0.5 * r0
        with np.errstate(invalid="ignore"):
            above = (cover >= 0.5) & search[None, :] & inside
        last = n - 1 - np.argmax(above[:, ::-1], axis=1)
        k_in = np.clip(last[:, None] - np.arange(2, 7)[None, :], 0, n - 1)  # 1-3 px inside the crossing
        a_k, c_k, b_k = hue_projection(prof[rows[:, None], k_in][..., ::-1], self.hue_deg)
        ball_inside = ((a_k > 0.45 * b_k) & (np.abs(c_k) < 0.35 * a_k) & (b_k > 30)).mean(axis=1) >= 0.5
        wrong = unmix & above.any(axis=1) & ~ball_inside
        use &= ~wrong
        fb = np.nonzero(ok & (~unmix | wrong))[0]
        if len(fb):  # the fallback, for those rays: hue projection with local levels
            hh = np.radians(self.hue_deg)
            pf = prof[fb]
            along = (pf[..., 0] - 0.5 * (pf[..., 1] + pf[..., 2])) * np.float32(np.cos(hh)) \
                + 0.8660254 * (pf[..., 1] - pf[..., 2]) * np.float32(np.sin(hh))
            ins = inside[fb]
            lev_in = np.median(along[:, inner], axis=1)
            lev_out = _row_median(along[:, outer], ins[:, outer])
            search = s > 0.5 * r0
            rf = np.arange(len(fb))
            okf = np.ones(len(fb), bool)
            win = np.arange(4, 13)[None, :]
            for _ in range(3):
                okf &= (lev_in - lev_out) > np.maximum(12.0, 0.3 * lev_in)
                below = (along < (0.5 * (lev_in + lev_out))[:, None]) & search[None, :]
                idx = np.argmax(below, axis=1)
                k_in = np.clip(idx[:, None] - win, 0, n - 1)
                k_out = np.clip(idx[:, None] + win, 0, n - 1)
                lev_in = np.median(along[rf[:, None], k_in], axis=1)
                lev_out = np.median(along[rf[:, None], k_out], axis=1)
            okf &= ins[rf[:, None], k_out].all(axis=1)
            val = val.copy()
            val[fb] = (along - lev_out[:, None]) / np.maximum(lev_in - lev_out, 1e-6)[:, None]
            use[fb] = okf
        # one profile per ray, ½ crossing
        # the outermost crossing: a marker, a highlight or a seam inside the ball does not stop the ray
        search = s > 0.5 * r0
        above = (val >= 0.5) & search[None, :] & inside
        last = n - 1 - np.argmax(above[:, ::-1], axis=1)
        idx = np.minimum(last + 1, n - 1)
        use &= above.any(axis=1) & (last + 1 < n) & inside[rows, idx]
        if not use.any():
            return np.zeros((0, 2))
        i, r = idx[use], rows[use]
        va, vb = val[r, i - 1], val[r, i]
        frac = np.where(va != vb, (va - 0.5) / np.where(va != vb, va - vb, 1.0), 0.0)
        rad = s[i - 1] + np.clip(frac, 0.0, 1.0) * step
        return centre[None, :] + rad[:, None] * dirs[use]

    def _fit(self, rgb, centre, r0, offset, n_rays, span=(0.35, 1.9)):
        pts = self._edge_points(rgb, centre, r0, offset, n_rays, span)
        if len(pts) < 8:
            return None
        u = self.camera.rays_interpolated(pts)
        thr = self.inlier_px / self.camera.fx
        fit = geom.ransac_circle(u, thr, iterations=48 if n_rays == self.n_rays else 64, rng=self._rng)
        if fit is None:
            return None
        c, alpha, mask = fit
        return c, alpha, mask, u, pts

    def detect(self, bgr: np.ndarray, hint=None) -> Detection | None:
        """The ball in a BGR frame, or None. ``hint`` = (centre_px, radius_px) from tracking (best: the
        tracker's position at the frame's exposure time, projected): the outline is measured from there
        first, then looked for by colour in a window around it; without a hint (or when nothing is found
        there) the whole frame is searched."""
        import cv2  # optional dependency: the camera extra (OpenCV)

        H, W = bgr.shape[:2]
        if hint is not None:  # tracking: rays straight from where the ball should be
            # a good prediction (the tracker's, at the exposure time) needs only the fine pass
            det = self._measure(bgr, np.asarray(hint[0], float), float(hint[1]), fine_only=True)
            if det is not None and det.inliers >= 0.85 * det.rays and det.residual_px < 0.5:
                return det
            det = self._measure(bgr, np.asarray(hint[0], float), float(hint[1]))
            if det is not None and det.inliers >= TRACK_INLIERS * det.rays:
                return det
        tries = []
        if hint is not None:
            (hu, hv), hr = hint
            m = 2.5 * hr + 24
            x0, x1 = int(max(0, hu - m)), int(min(W, hu + m + 1))
            y0, y1 = int(max(0, hv - m)), int(min(H, hv + m + 1))
            if x1 - x0 > 8 and y1 - y0 > 8:
                tries.append((x0, y0, x1, y1, 1))
        tries.append((0, 0, W, H, 2))
        for x0, y0, x1, y1, scale in tries:
            win = bgr[y0:y1, x0:x1]
            small = win if scale == 1 else cv2.resize(win, ((x1 - x0) // scale, (y1 - y0) // scale),
                                                          interpolation=cv2.INTER_AREA)
            cands = self._candidates(small, x0, y0, scale)
            if not cands:
                continue
            if scale == 1:  # tracking: the candidate nearest the last ball, in the window around it
                cands.sort(key=lambda c: np.linalg.norm(c[0] - np.asarray(hint[0])) / max(hint[1], 1.0)
                           - c[2] - 0.02 * c[1])
                for centre, r0, _ in cands[:3]:
                    det = self._measure(bgr, centre, r0)
                    if det is not None and det.inliers >= TRACK_INLIERS * det.rays:
                        det.candidates = len(cands)
                        return det
                continue
            # the whole frame (a cold start, or the track lost): measure the likeliest few and keep the
            # most circle-like outline, if it is clearly one
            cands.sort(key=lambda c: -(c[1] * c[2]))  # large and round first (a clipped disc is about half round)
            found = [d for d in (self._measure(bgr, centre, r0) for centre, r0, _ in cands[:5])
                     if d is not None and self.clear_outline(d)]
            if found:
                best = max(found, key=lambda d: d.inliers / self.n_rays - 0.1 * d.residual_px)
                best.candidates = len(cands)
                if self.colour is None:
                    self.colour = best.colour
                return best
        return None

    def clear_outline(self, d: Detection) -> bool:
        """Without a track, an outline counts as the ball when most of it is seen and fits a circle, or when
        half of it is seen and fits one sharply (the fit's own residual)."""
        n = self.n_rays
        return ((d.inliers >= COLD_START_INLIERS * n and d.residual_px <= COLD_START_RESIDUAL_PX)
                or (d.inliers >= PARTIAL_INLIERS * n and d.residual_px <= PARTIAL_RESIDUAL_PX))

    def _measure(self, bgr, centre, r0, fine_only: bool = False):
        H, W = bgr.shape[:2]
        out = None
        m = 1.9 * r0 + 10
        x0, x1 = int(max(0, centre[0] - m)), int(min(W, centre[0] + m + 2))
        y0, y1 = int(max(0, centre[1] - m)), int(min(H, centre[1] + m + 2))
        if x1 - x0 < 4 or y1 - y0 < 4:
            return None
        rgb = np.ascontiguousarray(bgr[y0:y1, x0:x1, ::-1], dtype=np.float32)
        # first 48 rays over a wide range; then 96 from the fitted centre, over the fitted outline ± 40 %
        fine = (self.n_rays, (0.6, 1.4))
        passes = [fine] if fine_only else [(self.n_rays // 2, (0.35, 1.9)), fine]
        while passes:
            n_rays, span = passes.pop(0)
            fit = self._fit(rgb, centre, r0, (x0, y0), n_rays, span)
            if fit is None:
                return out
            c, alpha, mask, u, pts = fit
            # the coarse pass from a candidate's centre may start well off a partly hidden ball's: a third of
            # its rays on one circle is enough to aim the fine pass, which decides
            if mask.sum() < max(8, (0.4 if n_rays == self.n_rays else 0.3) * len(u)):
                return out
            centre_new = self.camera.project(c[None, :])[0]
            r_new = float(np.mean(np.linalg.norm(pts[mask] - centre_new, axis=1)))
            if not (self.min_radius_px <= r_new <= 0.5 * max(W, H)) or not np.all(np.isfinite(centre_new)) \
                    or np.linalg.norm(centre_new - centre) > r0 + 2.0:
                return out
            if n_rays == self.n_rays:
                det = self._detection(c, alpha, u[mask], centre_new, r_new, len(u))
                det.colour = self._last_colour
                if out is not None and det.inliers < out.inliers:
                    return out
                # searched from a centre far off a partly hidden ball's: once more from the fitted one
                if out is None and not fine_only and det.inliers < COLD_START_INLIERS * self.n_rays:
                    passes.append(fine)
                out = det
            centre, r0 = centre_new, r_new
        return out

    def _detection(self, c, alpha, u_in, centre_px, r_px, n_rays) -> Detection:
        f = self.camera.fx
        theta = np.arccos(np.clip(u_in @ c, -1, 1))
        res = theta - alpha
        sigma = max(float(np.sqrt(np.mean(res * res))) * f, 0.15) / f  # rad; floor 0.15 px
        e1 = np.cross(c, [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(c, e1)
        t = u_in - np.outer(u_in @ c, c)
        phi = np.arctan2(t @ e2, t @ e1)
        J = np.stack([np.cos(phi), np.sin(phi), np.ones_like(phi)], 1)
        cov_p = sigma * sigma * np.linalg.inv(J.T @ J + 1e-12 * np.eye(3))
        D = self.radius_m / np.sin(alpha)
        G = np.stack([D * e1, D * e2, -D / np.tan(alpha) * c], 1)
        C = D * c
        return Detection(C, G @ cov_p @ G.T, centre_px, r_px, len(u_in), n_rays, float(np.sqrt(np.mean(res * res)) * f))


def blob_position(bgr: np.ndarray, camera: Camera, hue_deg: float = 120.0, radius_m: float = 0.04, hint=None):
    """The colour-blob method of the PlayStation Move's open trackers, as the issue describes it (written
    here from that description, for comparison): the pixels of the ball's colour, the largest region (or
    the one nearest the last), its centroid as the direction and its apparent size as the distance
    (D = f·R/r with r = √(area/π)). No sub-pixel outline, no perspective: what the hybrid is compared with.
    Returns the centre (camera frame, m) or None."""
    import cv2  # optional dependency: the camera extra (OpenCV)

    H, W = bgr.shape[:2]
    x0, y0, x1, y1 = 0, 0, W, H
    if hint is not None:
        (hu, hv), hr = hint
        m = 2.5 * hr + 24
        x0, x1 = int(max(0, hu - m)), int(min(W, hu + m + 1))
        y0, y1 = int(max(0, hv - m)), int(min(H, hv + m + 1))
        if x1 - x0 < 8 or y1 - y0 < 8:
            x0, y0, x1, y1 = 0, 0, W, H
    along, across, bright = hue_projection(bgr[y0:y1, x0:x1], hue_deg)
    mask = ((along > 0.45 * bright) & (np.abs(across) < 0.35 * along) & (bright > 30)).astype(np.uint8)
    n, labels, stats, cent = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return None
    areas = stats[1:, cv2.CC_STAT_AREA]
    if hint is not None:
        d = np.linalg.norm(cent[1:] + [x0, y0] - np.asarray(hint[0]), axis=1)
        k = int(np.argmin(d - 0.01 * areas)) + 1
    else:
        k = int(np.argmax(areas)) + 1
    area = float(stats[k, cv2.CC_STAT_AREA])
    if area < 12:
        return None
    c = cent[k] + [x0, y0]
    r = np.sqrt(area / np.pi)
    ray = camera.rays(c[None])[0]
    return ray / ray[2] * (camera.fx * radius_m / r)
