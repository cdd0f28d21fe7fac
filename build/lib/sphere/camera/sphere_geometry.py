"""The exact perspective image of a sphere, and the sphere from its outline.

A sphere of radius R with centre C (camera frame, |C| = D > R) is seen as the cone of rays tangent to
it: the unit rays u with u·c = cos α, c = C/D, sin α = R/D. On the image plane z = 1 a ray m = (x, y, 1)
is on the outline when (m·c)² = |m|² cos²α, i.e. mᵀ Q m = 0 with the conic

    Q = c cᵀ − cos²α · I.

Q's eigenvalues are 1 − cos²α = sin²α (eigenvector c) and −cos²α twice, so the outline is an ellipse
(for c_z > cos α ... i.e. the whole sphere in front of the camera) whose axis points away from the
principal point, and whose centre is NOT the projection of C: along that axis the outline runs from
tan(β − α) to tan(β + α) (β the angle of c from the optical axis), whose midpoint is further out than
tan β. At β = 30°, α = 4.6° (8 cm ball at 0.5 m) the difference is 0.005 in normalised units (3 px on a
640-px, 60° webcam).

The inverse uses the same fact without fitting an ellipse: the outline's rays, as unit vectors, lie on
a small circle of the unit sphere, i.e. in the plane c·u = cos α. Three rays fix that plane (the
minimal sample for RANSAC); the least-squares plane through many of them minimises, to first order,
the angular residuals (the distance to the plane is cos θ − cos α ≈ sin α · (α − θ), the same factor
for every ray). Then C = (R / sin α) c.
"""

from __future__ import annotations

import numpy as np


def outline_cone(center_cam, radius_m: float) -> tuple[np.ndarray, float]:
    """(c, α): unit direction of the centre and the half-angle of the tangent cone."""
    C = np.asarray(center_cam, float)
    D = float(np.linalg.norm(C))
    if D <= radius_m:
        raise ValueError("the camera is inside the sphere")
    return C / D, float(np.arcsin(radius_m / D))


def image_conic(center_cam, radius_m: float) -> np.ndarray:
    """The outline as a conic on the normalised image plane: mᵀ Q m = 0 for m = (x, y, 1)."""
    c, a = outline_cone(center_cam, radius_m)
    return np.outer(c, c) - np.cos(a) ** 2 * np.eye(3)


def outline_points(center_cam, radius_m: float, n: int = 360) -> np.ndarray:
    """n points of the outline in normalised image coordinates (N, 2)."""
    c, a = outline_cone(center_cam, radius_m)
    e1 = np.cross(c, [0.0, 1.0, 0.0] if abs(c[1]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(c, e1)
    phi = np.linspace(0, 2 * np.pi, n, endpoint=False)
    u = np.cos(a) * c + np.sin(a) * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    return u[:, :2] / u[:, 2:3]


def ellipse_center(center_cam, radius_m: float) -> np.ndarray:
    """Centre of the outline ellipse in normalised coordinates (from the conic: Q₂ₓ₂ m = −q)."""
    Q = image_conic(center_cam, radius_m)
    return np.linalg.solve(Q[:2, :2], -Q[:2, 2])


def circle_from_rays(u: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares small circle through unit rays (N ≥ 3, 3): (c, α)."""
    m = u.mean(axis=0)
    _, _, vt = np.linalg.svd(u - m, full_matrices=False)
    n = vt[-1]
    d = float(n @ m)
    if d < 0:
        n, d = -n, -d
    return n, float(np.arccos(np.clip(d, -1.0, 1.0)))


def sphere_from_cone(c: np.ndarray, alpha: float, radius_m: float) -> np.ndarray:
    """Centre of the sphere of radius R seen under the cone (c, α)."""
    return (radius_m / np.sin(alpha)) * np.asarray(c, float)


def sphere_from_conic(Q: np.ndarray, radius_m: float) -> np.ndarray:
    """Centre of the sphere from its outline conic (any scale or sign): the eigen-structure of
    Q ∝ c cᵀ − cos²α I gives c (the eigenvector of the odd eigenvalue) and cos²α = 1 / (1 − λ₁/λ₂)."""
    Q = np.asarray(Q, float)
    Q = 0.5 * (Q + Q.T)
    w, v = np.linalg.eigh(Q)
    # the odd one out has the opposite sign to the other two
    signs = np.sign(w)
    odd = int(np.argmax(signs)) if (signs > 0).sum() == 1 else int(np.argmin(signs))
    pair = [i for i in range(3) if i != odd]
    r = w[odd] / np.mean(w[pair])
    cos2 = 1.0 / (1.0 - r)
    c = v[:, odd]
    if c[2] < 0:
        c = -c
    return sphere_from_cone(c, float(np.arccos(np.sqrt(np.clip(cos2, 0.0, 1.0)))), radius_m)


def ransac_circle(u: np.ndarray, threshold_rad: float, iterations: int = 64, rng=None):
    """Robust small circle through unit rays: RANSAC on minimal samples of 3, then least squares on the
    inliers (twice). Returns (c, α, inlier mask) or None when fewer than 5 rays agree."""
    n = len(u)
    if n < 5:
        return None
    rng = np.random.default_rng(0) if rng is None else rng
    idx = rng.integers(0, n, (2 * iterations, 3))
    idx = idx[(idx[:, 0] != idx[:, 1]) & (idx[:, 0] != idx[:, 2]) & (idx[:, 1] != idx[:, 2])][:iterations]
    a, b, cc = u[idx[:, 0]], u[idx[:, 1]], u[idx[:, 2]]
    nrm = np.cross(b - a, cc - a)
    ln = np.linalg.norm(nrm, axis=1)
    ok = ln > 1e-12
    if not ok.any():
        return None
    nrm = nrm[ok] / ln[ok, None]
    d = np.einsum("ij,ij->i", nrm, a[ok])
    flip = d < 0
    nrm[flip] *= -1
    d[flip] *= -1
    # |cos θ − cos α| ≈ sin α · |θ − α|: the angular residual without an arccos per ray and hypothesis
    sin_a = np.sqrt(np.maximum(1.0 - d * d, 1e-12))
    inl = np.abs(u @ nrm.T - d[None, :]) < threshold_rad * sin_a[None, :]
    counts = inl.sum(axis=0)
    best = int(np.argmax(counts))
    mask = inl[:, best]
    if mask.sum() < 5:
        return None
    for _ in range(2):
        c, al = circle_from_rays(u[mask])
        res = np.abs(np.arccos(np.clip(u @ c, -1, 1)) - al)
        new = res < threshold_rad
        if new.sum() < 5:
            break
        mask = new
    # last: the inliers by the fit's own spread (3σ, at least a quarter of the threshold), so points
    # just inside the threshold (where a hand's edge meets the outline) do not pull the fit
    c, al = circle_from_rays(u[mask])
    res = np.abs(np.arccos(np.clip(u @ c, -1, 1)) - al)
    tight = res < max(3.0 * float(np.sqrt(np.mean(res[mask] ** 2))), 0.25 * threshold_rad)
    if tight.sum() >= max(5, 0.8 * mask.sum()):
        mask = tight
        c, al = circle_from_rays(u[mask])
    return c, al, mask
