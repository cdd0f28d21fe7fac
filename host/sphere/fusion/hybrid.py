"""The hybrid computer-vision + sensor-fusion tracker of the dissertation's chapter 3 (seed digest §6).

Two Kalman filters behind one interface that any pose source can feed:

- :class:`OrientationKF` — per angle (φ, θ, ψ), A = H = I. The CV orientation is the *process*
  (Q = 10⁻⁴, trusted), the SF orientation the *measurement* (R = 10). The first CV sample initialises
  the state. When no CV sample arrived for this tick, the SF orientation is used in the prediction with
  the same confidence as CV. Outlier gate (eq. 104/24): if |innovation| < |z|·z_TH the process (CV) is
  kept, otherwise the measurement (SF) is trusted (the state takes z), z_TH = 5 %.
- :class:`PositionKF` — per axis, constant-acceleration model
  A = [[1, Δt, Δt²/2], [0, 1, Δt], [0, 0, 1]], H = [1, 0, 0], R = 10⁻⁴ (trust CV). The SF acceleration
  drives the process (it sets the acceleration state each SF tick). The control input of eq. 105–107,
  B = diag(1, 0, 0), u = [ŷᵐ, 0, 0], ŷᵐ = ŷ + (f_cv/f_sf)·Σ(zᵢ − zᵢ₋₁)/(n − 1) over the last n = 4 CV
  samples, keeps the SF prediction from drifting between CV frames. **Our reading** of eq. 107 (the text
  leaves ŷ's timing open): on an SF tick, the position prediction moves by the CV trend per SF tick,
  (f_cv/f_sf)·mean(Δz), plus the last CV innovation ŷ spread over the SF ticks of one CV period,
  (f_cv/f_sf)·ŷ; velocity and acceleration follow A with the SF acceleration. With fewer than n CV
  samples so far, or during a CV dropout longer than one period, the trend term is the last known one
  and ŷ is not re-applied.
- :class:`HybridTracker` — both, fed by ``sensor(t, angles_deg, accel)`` at the SF rate and
  ``camera(t, angles_deg, position)`` at the CV rate (None when the camera lost the target). Any pose
  source with that shape (a marker tracker, a phone's AR session) can drive it.

:func:`simulate` reproduces chapter 3's simulation with a fixed seed; ``sphere hybrid-sim`` prints the
tables beside the dissertation's Tables 2–3.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


class OrientationKF:
    """Chapter 3's orientation filter for a vector of angles (degrees)."""

    def __init__(self, n: int = 3, q: float = 1e-4, r: float = 10.0, z_th: float = 0.05):
        self.n, self.q, self.r, self.z_th = n, q, r, z_th
        self.x = None  # state: angles
        self.p = np.full(n, q)
        self.innovation = np.zeros(n)
        self.trusted_measurement = np.zeros(n, bool)

    def step(self, sf_deg, cv_deg=None) -> np.ndarray:
        z = np.asarray(sf_deg, float)
        if self.x is None:
            if cv_deg is None:
                return np.full(self.n, np.nan)  # the first CV sample initialises the state
            self.x = np.asarray(cv_deg, float).copy()
        # prediction: the process is CV; without a CV sample this tick, SF with the same confidence
        x_pred = np.asarray(cv_deg, float) if cv_deg is not None else z.copy()
        p_pred = self.q + 0.0 * self.p  # A = I and the state is re-seeded from the process each tick
        nu = z - x_pred
        self.innovation = nu
        k = p_pred / (p_pred + self.r)
        gate = np.abs(nu) < np.abs(z) * self.z_th  # eq. 24: keep trusting the process
        self.trusted_measurement = ~gate
        self.x = np.where(gate, x_pred + k * nu, z)
        self.p = np.where(gate, (1.0 - k) * p_pred, self.r * p_pred / (p_pred + self.r))
        return self.x.copy()


class PositionKF:
    """Chapter 3's constant-acceleration position filter for one axis, with the control input (n = 4)."""

    def __init__(self, dt_sf: float = 0.01, f_cv: float = 20.0, f_sf: float = 100.0, r: float = 1e-4,
                 q: float = 1e-6, n: int = 4, x0=(0.0, 0.0, 0.0)):
        self.dt = dt_sf
        self.ratio = f_cv / f_sf
        self.A = np.array([[1.0, dt_sf, 0.5 * dt_sf * dt_sf], [0.0, 1.0, dt_sf], [0.0, 0.0, 1.0]])
        self.H = np.array([1.0, 0.0, 0.0])
        self.r = r
        self.Q = q * np.eye(3)
        self.n = n
        self.x = np.array(x0, float)
        self.P = np.eye(3) * 1e-4
        self.z_hist: list[tuple[int, float]] = []  # (SF tick, CV position) of the last n CV samples
        self.y_last = 0.0
        self.ticks_since_cv = 0
        self.tick = 0

    def _trend(self) -> float:
        """Σ(zᵢ − zᵢ₋₁)/(n − 1): the mean CV step per CV period over the last n samples (a dropout
        between them counts as the periods it lasted)."""
        z = self.z_hist[-self.n:]
        if len(z) < 2:
            return 0.0
        periods = (z[-1][0] - z[0][0]) * self.ratio
        return (z[-1][1] - z[0][1]) / periods if periods > 0 else 0.0

    def step(self, sf_accel: float, cv_pos: float | None = None) -> float:
        x = self.x.copy()
        x[2] = sf_accel  # the SF acceleration drives the process
        x = self.A @ x
        # control input B u, u = [ŷᵐ, 0, 0]
        self.ticks_since_cv += 1
        self.tick += 1
        if len(self.z_hist) >= 2:
            per_period = round(1.0 / self.ratio)
            y = self.y_last if self.ticks_since_cv <= per_period else 0.0
            u = self.ratio * (y + self._trend())
            x[0] = self.x[0] + u  # the CV trend replaces the SF double integration for position
        self.P = self.A @ self.P @ self.A.T + self.Q
        if cv_pos is not None:
            s = self.P[0, 0] + self.r
            k = self.P[:, 0] / s
            y = cv_pos - x[0]
            x = x + k * y
            self.P = self.P - np.outer(k, self.P[0, :])
            self.y_last = float(cv_pos - x[0]) if len(self.z_hist) >= 2 else 0.0
            self.z_hist.append((self.tick, float(cv_pos)))
            self.z_hist = self.z_hist[-self.n:]
            self.ticks_since_cv = 0
        self.x = x
        return float(x[0])


@dataclass
class HybridTracker:
    """Orientation and position from a sensor-fusion source (SF rate) and a pose source (CV rate)."""

    dt_sf: float = 0.01
    f_cv: float = 20.0
    orientation: OrientationKF = field(default_factory=OrientationKF)
    positions: list = field(default_factory=list)

    def __post_init__(self):
        if not self.positions:
            self.positions = [PositionKF(self.dt_sf, self.f_cv, 1.0 / self.dt_sf) for _ in range(3)]
        self._cv = None

    def camera(self, angles_deg, position_m) -> None:
        """A pose from the camera (or any pose source); call with None when the target is lost."""
        self._cv = None if angles_deg is None else (np.asarray(angles_deg, float), np.asarray(position_m, float))

    def sensor(self, angles_deg, accel_m_s2):
        """One SF tick: returns (angles_deg, position_m) of the hybrid estimate."""
        cv = self._cv
        self._cv = None
        ang = self.orientation.step(angles_deg, None if cv is None else cv[0])
        pos = np.array([f.step(a, None if cv is None else cv[1][i]) for i, (f, a) in
                        enumerate(zip(self.positions, accel_m_s2))])
        return ang, pos


# -- chapter 3's simulation ---------------------------------------------------------------------------

#: Tables 2–3 of the dissertation (001 English summary): mean, σ, RMSE; RMSPE in %.
DISSERTATION = {
    "orientation": {"GT": (90.00, 63.67, None, None), "SF": (90.30, 63.73, 89.73, 0.30),
                    "CV": (88.55, 63.84, 90.27, 0.30), "KF": (90.28, 63.68, 89.79, 0.24)},
    "position": {"GT": (0.31, 0.35, None, None), "SF": (0.34, 0.38, 0.04, 13.06),
                 "CV": (0.32, 0.36, 0.06, 19.75), "KF": (0.31, 0.35, 0.003, 0.96)},
}

SEED = 20240611


@dataclass
class SimResult:
    t: np.ndarray
    orientation: dict  # name → (N,) degrees
    position: dict  # name → (N,) metres
    cv_valid: np.ndarray
    cv_spike: np.ndarray


def simulate(seed: int = SEED, duration_s: float = 20.0, f_sf: float = 100.0, f_cv: float = 20.0,
             sweep_hz: float = 0.05, sf_sigma_deg: float = 0.2, cv_sigma_deg: float = 0.2,
             spike_prob: float = 0.03, spike_deg=(20.0, 60.0), dropouts=((4.0, 5.0), (11.0, 12.5)),
             acc_sigma: float = 0.2, cv_pos_sigma: float = 0.005) -> SimResult:
    """Chapter 3's simulation, one axis, reproducible with ``seed``.

    Ground truth: φ(t) = 90° + 90°·sin(2π f t) (swept 0–180° from 90°; its mean 90° and σ 63.6° match
    Table 2's GT), position p(t) = 0.31 + 0.495·sin(2π f t) m (mean 0.31, σ 0.35 as Table 3's GT).
    SF: φ + N(0, σ=0.2°) at 100 Hz; acceleration p̈ + N(0, 0.2) m/s² integrated twice (eq. 88–89).
    CV at 20 Hz: φ + N(0, 0.2°) with spikes (3 % of frames, ±20–60°) and dropouts (occlusions), and
    p + N(0, 5 mm). SF and KF are compared at the SF rate; CV's own row uses the frames it delivered
    (NaN elsewhere), spikes included.
    """
    rng = np.random.default_rng(seed)
    dt = 1.0 / f_sf
    n = int(round(duration_s * f_sf))
    t = np.arange(n) * dt
    w = 2 * np.pi * sweep_hz
    gt_o = 90.0 + 90.0 * np.sin(w * t)
    gt_p = 0.31 + 0.495 * np.sin(w * t)
    gt_a = -0.495 * w * w * np.sin(w * t)
    sf_o = gt_o + rng.normal(0.0, sf_sigma_deg, n)
    acc = gt_a + rng.normal(0.0, acc_sigma, n)
    sf_p = np.empty(n)
    p, v = gt_p[0], 0.495 * w  # common origin: SF starts from the true state
    for i in range(n):
        if i:
            p = p + v * dt + 0.5 * acc[i] * dt * dt
            v = v + acc[i] * dt
        sf_p[i] = p
    every = int(round(f_sf / f_cv))
    cv_tick = (np.arange(n) % every) == 0
    lost = np.zeros(n, bool)
    for a, b in dropouts:
        lost |= (t >= a) & (t < b)
    cv_valid = cv_tick & ~lost
    spike = cv_valid & (rng.random(n) < spike_prob)
    cv_o_raw = gt_o + rng.normal(0.0, cv_sigma_deg, n)
    cv_o_raw[spike] += rng.choice([-1.0, 1.0], spike.sum()) * rng.uniform(*spike_deg, spike.sum())
    cv_p_raw = gt_p + rng.normal(0.0, cv_pos_sigma, n)

    trk_o = OrientationKF(n=1)
    trk_p = PositionKF(dt, f_cv, f_sf, x0=(gt_p[0], 0.495 * w, 0.0))
    kf_o = np.empty(n)
    kf_p = np.empty(n)
    cv_o = np.empty(n)
    cv_p = np.empty(n)
    for i in range(n):
        c = cv_valid[i]
        cv_o[i], cv_p[i] = (cv_o_raw[i], cv_p_raw[i]) if c else (np.nan, np.nan)
        kf_o[i] = trk_o.step([sf_o[i]], [cv_o_raw[i]] if c else None)[0]
        kf_p[i] = trk_p.step(acc[i], cv_p_raw[i] if c else None)
    return SimResult(t, {"GT": gt_o, "SF": sf_o, "CV": cv_o, "KF": kf_o},
                     {"GT": gt_p, "SF": sf_p, "CV": cv_p, "KF": kf_p}, cv_valid, spike)


def table(values: dict) -> dict:
    """name → (mean, σ, RMSE of the error, RMSPE % (eq. 109, RMSE/μ_GT), RMS of the signal itself)."""
    gt = values["GT"]
    out = {}
    for name, x in values.items():
        ok = np.isfinite(x)
        e = x[ok] - gt[ok]
        rmse = float(np.sqrt(np.mean(e * e))) if name != "GT" else None
        rmspe = 100.0 * rmse / float(np.mean(gt)) if rmse is not None else None
        out[name] = (float(np.mean(x[ok])), float(np.std(x[ok])), rmse, rmspe, float(np.sqrt(np.mean(x[ok] ** 2))))
    return out
