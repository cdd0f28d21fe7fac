"""Calibration math for the sphere's three sensors: pure functions on arrays in chip units (LSB).

- :func:`gyro_bias` — ITG-3200 bias from a still capture (mean), with a check that it *was* still.
- :func:`accel_six_position` — ADXL345 per-axis offset and gain from the means of ≥ 6 still poses
  (each axis up and down), by least squares on ‖gain·(a − offset)‖ = 1 g.
- :func:`mag_ellipsoid` — HMC5883L hard iron (centre) and soft iron (3×3 symmetric matrix) from a cloud
  of readings taken while turning the sphere every way: an algebraic ellipsoid fit
  (x − c)ᵀ M (x − c) = 1, soft iron W = √M scaled so the corrected field keeps the cloud's mean radius.
  Reports the fit residual and the field norm before and after.
- :func:`still_segments` / :func:`from_capture` — find still phases in one capture and run all three.

Conventions (the firmware applies them in this form, so every number is ready for fixed point):
  gyro_corrected  = gyro_raw − gyro_bias                      (LSB)
  accel_corrected = (accel_raw − accel_offset) · accel_gain   (LSB; 1 g = 256 LSB afterwards)
  mag_corrected   = mag_soft_iron · (mag_raw − mag_hard_iron) (LSB; same mean field norm as before)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from sphere import chips

ACCEL_1G_LSB = chips.ADXL345_LSB_PER_G


@dataclass
class GyroBias:
    bias_lsb: np.ndarray  # (3,)
    noise_lsb: np.ndarray  # (3,) standard deviation while still
    samples: int

    def as_dict(self) -> dict:
        return {"bias_lsb": self.bias_lsb.tolist(), "noise_lsb": self.noise_lsb.tolist(), "samples": self.samples,
                "bias_dps": (self.bias_lsb / chips.ITG3200_LSB_PER_DPS).tolist()}


@dataclass
class AccelCalibration:
    offset_lsb: np.ndarray  # (3,)
    gain: np.ndarray  # (3,) dimensionless; 1 g = 256 LSB after correction
    residual_lsb: float  # RMS of ‖corrected‖ − 256 over the poses
    poses: int

    def apply(self, raw) -> np.ndarray:
        return (np.asarray(raw, float) - self.offset_lsb) * self.gain

    def as_dict(self) -> dict:
        return {"offset_lsb": self.offset_lsb.tolist(), "gain": self.gain.tolist(),
                "residual_lsb": self.residual_lsb, "poses": self.poses}


@dataclass
class MagCalibration:
    hard_iron_lsb: np.ndarray  # (3,)
    soft_iron: np.ndarray  # (3, 3) symmetric, dimensionless
    radius_lsb: float  # field norm the corrected readings share
    residual: float  # RMS of (‖corrected‖ − radius) / radius
    norm_before: tuple  # (mean, std) of ‖raw‖, LSB
    norm_after: tuple  # (mean, std) of ‖corrected‖, LSB
    samples: int

    def apply(self, raw) -> np.ndarray:
        return (np.asarray(raw, float) - self.hard_iron_lsb) @ self.soft_iron.T

    def as_dict(self) -> dict:
        return {"hard_iron_lsb": self.hard_iron_lsb.tolist(), "soft_iron": self.soft_iron.tolist(),
                "radius_lsb": self.radius_lsb, "radius_uT": self.radius_lsb / chips.HMC5883L_LSB_PER_UT,
                "residual": self.residual, "norm_before_lsb": list(self.norm_before),
                "norm_after_lsb": list(self.norm_after), "samples": self.samples}


@dataclass
class Calibration:
    gyro: GyroBias | None = None
    accel: AccelCalibration | None = None
    mag: MagCalibration | None = None
    notes: list = field(default_factory=list)

    def as_dict(self) -> dict:
        return {k: (v.as_dict() if v is not None else None) for k, v in
                (("gyro", self.gyro), ("accel", self.accel), ("mag", self.mag))} | {"notes": list(self.notes)}


def gyro_bias(gyro_lsb, max_std_lsb: float = 30.0) -> GyroBias:
    """Bias = mean of a still capture. Raises ValueError when the capture moved (std above ``max_std_lsb``)."""
    g = np.asarray(gyro_lsb, float)
    if g.ndim != 2 or g.shape[1] != 3 or len(g) < 10:
        raise ValueError("gyro_bias needs an (N ≥ 10, 3) array of raw gyro samples")
    std = g.std(axis=0)
    if np.any(std > max_std_lsb):
        raise ValueError(f"the sphere moved while the gyro bias was measured (std {std.round(1).tolist()} LSB > "
                         f"{max_std_lsb}); keep it still and try again")
    return GyroBias(g.mean(axis=0), std, len(g))


def accel_six_position(pose_means_lsb) -> AccelCalibration:
    """Offset and gain per axis from the mean accelerometer reading of each still pose (≥ 6 poses,
    each axis once pointing up and once down)."""
    m = np.asarray(pose_means_lsb, float)
    if m.ndim != 2 or m.shape[1] != 3 or len(m) < 6:
        raise ValueError("accel_six_position needs the means of at least 6 still poses, shape (≥6, 3)")
    hi, lo = m.max(axis=0), m.min(axis=0)
    if np.any(hi < 0.5 * ACCEL_1G_LSB) or np.any(lo > -0.5 * ACCEL_1G_LSB):
        raise ValueError("each accelerometer axis must point once up and once down (six faces of the sphere)")
    off0 = (hi + lo) / 2.0
    gain0 = 2.0 * ACCEL_1G_LSB / (hi - lo)

    def resid(p):
        return np.linalg.norm((m - p[:3]) * p[3:], axis=1) - ACCEL_1G_LSB

    r = least_squares(resid, np.concatenate([off0, gain0]))
    off, gain = r.x[:3], r.x[3:]
    return AccelCalibration(off, gain, float(np.sqrt(np.mean(resid(r.x) ** 2))), len(m))


def mag_ellipsoid(mag_lsb) -> MagCalibration:
    """Hard and soft iron from readings covering many orientations (an ellipsoid fit)."""
    x = np.asarray(mag_lsb, float)
    if x.ndim != 2 or x.shape[1] != 3 or len(x) < 20:
        raise ValueError("mag_ellipsoid needs an (N ≥ 20, 3) array of raw magnetometer samples")
    x = x[np.all(x != chips.HMC5883L_OVERFLOW, axis=1)]
    # coverage: a cloud from turning about one axis only is a flat ring, not an ellipsoid
    spread = np.sqrt(np.linalg.eigvalsh(np.cov((x - x.mean(axis=0)).T)))
    if spread[0] < 0.15 * spread[-1]:
        raise ValueError("the magnetometer readings do not cover enough orientations for an ellipsoid fit "
                         f"(spread {spread.round(0).tolist()} LSB; turn the sphere through every direction)")
    # centre and scale for conditioning
    mu = x.mean(axis=0)
    s = np.abs(x - mu).max()
    u = (x - mu) / s
    a, b, c = u[:, 0], u[:, 1], u[:, 2]
    D = np.column_stack([a * a, b * b, c * c, 2 * a * b, 2 * a * c, 2 * b * c, 2 * a, 2 * b, 2 * c])
    p, *_ = np.linalg.lstsq(D, np.ones(len(u)), rcond=None)
    A = np.array([[p[0], p[3], p[4]], [p[3], p[1], p[5]], [p[4], p[5], p[2]]])
    bvec = p[6:9]
    try:
        centre_u = -np.linalg.solve(A, bvec)
    except np.linalg.LinAlgError:
        raise ValueError("the magnetometer readings do not cover enough orientations for an ellipsoid fit") from None
    k = 1.0 + centre_u @ A @ centre_u
    M = A / k
    w, V = np.linalg.eigh(M)
    if np.any(w <= 0):
        raise ValueError("the magnetometer readings do not cover enough orientations for an ellipsoid fit "
                         "(turn the sphere through every direction)")
    semi = 1.0 / np.sqrt(w)  # semi-axes in scaled units
    radius_u = float(np.prod(semi) ** (1.0 / 3.0))
    W = V @ np.diag(np.sqrt(w) * radius_u) @ V.T  # maps the ellipsoid to a sphere of radius radius_u
    centre = mu + s * centre_u
    radius = radius_u * s
    corrected = (x - centre) @ W.T
    nb = np.linalg.norm(x, axis=1)
    na = np.linalg.norm(corrected, axis=1)
    residual = float(np.sqrt(np.mean(((na - radius) / radius) ** 2)))
    return MagCalibration(centre, W, radius, residual, (float(nb.mean()), float(nb.std())),
                          (float(na.mean()), float(na.std())), len(x))


def still_segments(gyro_lsb, accel_lsb, rate_hz: float, min_s: float = 1.0, gyro_th_dps: float = 3.0,
                   accel_th_lsb: float = 8.0) -> list[tuple[int, int]]:
    """Index ranges [start, stop) where the sphere lay still for at least ``min_s`` seconds."""
    g = np.asarray(gyro_lsb, float) / chips.ITG3200_LSB_PER_DPS
    a = np.asarray(accel_lsb, float)
    n = len(g)
    w = max(3, int(round(0.25 * rate_hz)))
    still = np.zeros(n, bool)
    # rolling std over windows of w samples, via cumulative sums
    def rolling_std(x):
        c1 = np.cumsum(np.vstack([np.zeros((1, 3)), x]), axis=0)
        c2 = np.cumsum(np.vstack([np.zeros((1, 3)), x * x]), axis=0)
        s1 = c1[w:] - c1[:-w]
        s2 = c2[w:] - c2[:-w]
        var = np.maximum(s2 / w - (s1 / w) ** 2, 0.0)
        return np.sqrt(var.sum(axis=1))
    if n >= w:
        gs, as_ = rolling_std(g), rolling_std(a)
        ok = (gs < gyro_th_dps) & (as_ < accel_th_lsb)
        for i in np.flatnonzero(ok):
            still[i:i + w] = True
    segs = []
    i = 0
    while i < n:
        if still[i]:
            j = i
            while j < n and still[j]:
                j += 1
            if j - i >= min_s * rate_hz:
                segs.append((i, j))
            i = j
        else:
            i += 1
    return segs


def pose_means(accel_lsb, segments) -> np.ndarray:
    """Mean accelerometer reading of each still segment, merging segments in the same pose (within 20°)."""
    a = np.asarray(accel_lsb, float)
    means = [a[s:e].mean(axis=0) for s, e in segments]
    merged: list[list] = []
    for m in means:
        for group in merged:
            ref = group[0]
            cos = m @ ref / (np.linalg.norm(m) * np.linalg.norm(ref))
            if cos > np.cos(np.radians(20)):
                group.append(m)
                break
        else:
            merged.append([m])
    return np.array([np.mean(g, axis=0) for g in merged])


def from_capture(accel_lsb, gyro_lsb, mag_lsb, rate_hz: float) -> Calibration:
    """Everything from one capture: still phases give the gyro bias and the accelerometer poses; all
    magnetometer samples give the ellipsoid. A part that cannot be computed is left None with a note."""
    cal = Calibration()
    segs = still_segments(gyro_lsb, accel_lsb, rate_hz)
    if segs:
        g = np.asarray(gyro_lsb, float)
        still = np.concatenate([g[s:e] for s, e in segs])
        try:
            cal.gyro = gyro_bias(still)
        except ValueError as e:
            cal.notes.append(f"gyro: {e}")
    else:
        cal.notes.append("gyro: no still phase of 1 s or more in the capture")
    poses = pose_means(accel_lsb, segs) if segs else np.zeros((0, 3))
    try:
        cal.accel = accel_six_position(poses)
    except ValueError as e:
        cal.notes.append(f"accel: {e} (found {len(poses)} distinct still poses)")
    try:
        cal.mag = mag_ellipsoid(mag_lsb)
    except ValueError as e:
        cal.notes.append(f"mag: {e}")
    return cal


def plot_mag_cloud(mag_lsb, cal: MagCalibration, path) -> None:
    """PNG of the magnetometer cloud before and after calibration (three projections each)."""
    import matplotlib  # optional dependency: the plot extra

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional dependency: the plot extra

    raw = np.asarray(mag_lsb, float)
    cor = cal.apply(raw)
    fig, axes = plt.subplots(2, 3, figsize=(12, 8))
    for row, (data, title) in enumerate(((raw, "raw"), (cor, "calibrated"))):
        for col, (i, j) in enumerate(((0, 1), (0, 2), (1, 2))):
            ax = axes[row, col]
            ax.plot(data[:, i], data[:, j], ".", ms=1.5)
            if row == 1:
                t = np.linspace(0, 2 * np.pi, 200)
                ax.plot(cal.radius_lsb * np.cos(t), cal.radius_lsb * np.sin(t), "r-", lw=0.8)
            ax.set_aspect("equal")
            ax.set_xlabel("xyz"[i] + " (LSB)")
            ax.set_ylabel("xyz"[j] + " (LSB)")
            ax.set_title(f"{title}: {'xyz'[i]}{'xyz'[j]}")
    fig.suptitle(f"magnetometer: norm {cal.norm_before[0]:.0f}±{cal.norm_before[1]:.0f} → "
                 f"{cal.norm_after[0]:.0f}±{cal.norm_after[1]:.0f} LSB, residual {100 * cal.residual:.1f} %")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
