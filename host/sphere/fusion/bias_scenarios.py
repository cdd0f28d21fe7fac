"""Synthetic MARG traces with known truth (orientation and gyro bias), for testing bias estimation.

Written from the physics, not from any filter: a true orientation is integrated from a smooth angular
rate; the sensors read what that motion produces (specific force = R(q)ᵀ(a_lin + g·up), field =
R(q)ᵀ m_earth, rate = ω + bias) plus white noise of the sphere's chips (ITG-3200: 0.38 °/s rms at 100 Hz
bandwidth, datasheet "Total RMS noise"; ADXL345 ±2 g: about 1 LSB = 3.9 mg; HMC5883L: 0.2 µT).
Earth frame ENU (x east, y north, z up); q is sensor → earth, ``[w, x, y, z]``.

Every scenario rests for ``REST_S`` = 2 s and then moves continuously to the end (no rest again):
hand-like turns of 40–90 °/s about changing axes and hand translations of a few centimetres (linear
acceleration up to about 2 m/s²). The scenarios (:data:`SCENARIOS`):

- ``"motion"``: a constant bias, nothing else;
- ``"step"``: the bias jumps by :data:`STEP_DPS` at ``STEP_AT_S`` (while moving);
- ``"ramp"``: a warm-up ramp, the bias grows by 0.5 °/s over 5 min (``RAMP_DPS_PER_S``) from t = 0;
- ``"magnet"``: a constant bias with a magnet riding on the sensor from the first sample (a constant field
  of 25 µT in sensor axes, half the earth's: the measured field's norm and dip change as the sphere turns).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sphere import quaternion as quat
from sphere.chips import STANDARD_GRAVITY_M_S2

DEG = np.pi / 180.0
G = STANDARD_GRAVITY_M_S2
REST_S = 2.0
#: the bias at power-on (°/s per axis): what a start-up calibration that was not done leaves
BIAS0_DPS = np.array([0.35, -0.25, 0.30])
STEP_AT_S = 8.0
STEP_DPS = np.array([-0.4, 0.3, 0.35])
RAMP_DPS_PER_S = 0.5 / 300.0
RAMP_DIR = np.array([1.0, -0.6, 0.8]) / np.linalg.norm([1.0, -0.6, 0.8])
EARTH_FIELD_UT = 50.0
DIP_DEG = 66.0
MAGNET_UT = np.array([15.0, -12.0, 16.0])  # |.| ≈ 25 µT
GYRO_NOISE_DPS = 0.38
ACC_NOISE_M_S2 = 3.9e-3 * G
MAG_NOISE_UT = 0.2
SCENARIOS = ("motion", "step", "ramp", "magnet")


@dataclass(frozen=True)
class Trace:
    name: str
    dt_s: float
    gyr_rad_s: np.ndarray  # (N, 3) measured, with bias and noise
    acc_m_s2: np.ndarray  # (N, 3)
    mag_uT: np.ndarray  # (N, 3)
    quat: np.ndarray  # (N, 4) true sensor → ENU
    bias_rad_s: np.ndarray  # (N, 3) the true gyro bias

    @property
    def t(self) -> np.ndarray:
        return np.arange(len(self.gyr_rad_s)) * self.dt_s


def _smooth_gate(t, rest_s=REST_S):
    """0 during the rest, rising to 1 over 0.5 s after it (so motion starts without a jump)."""
    x = np.clip((t - rest_s) / 0.5, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def integrate_rate(w: np.ndarray, dt: float, q0) -> np.ndarray:
    """The true orientation (N, 4) from a body rate w (N, 3, rad/s; sample i the mean rate over (t[i−1], t[i]]):
    an exact axis-angle step for each interval, q[i] = q[i−1] ⊗ exp(½ w[i] dt), from q[0] = q0."""
    n = len(w)
    q = np.empty((n, 4))
    q[0] = q0
    ang = np.linalg.norm(w, axis=1) * dt
    axis = w / np.maximum(np.linalg.norm(w, axis=1), 1e-300)[:, None]
    dq = np.concatenate([np.cos(ang / 2)[:, None], np.sin(ang / 2)[:, None] * axis], axis=1)
    for i in range(1, n):
        q[i] = quat.multiply(q[i - 1], dq[i])
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def earth_field(field_ut: float = EARTH_FIELD_UT, dip_deg: float = DIP_DEG) -> np.ndarray:
    """The earth's field in ENU (µT): north (+y) and down by the dip."""
    return field_ut * np.array([0.0, np.cos(dip_deg * DEG), -np.sin(dip_deg * DEG)])


def trace(scenario: str, seconds: float = 40.0, rate_hz: float = 200.0, seed: int = 0, *,
          translation: float = 1.0, noise: float = 1.0, bias0_dps=BIAS0_DPS, rest_s: float = REST_S) -> Trace:
    """One synthetic trace; see the module docstring for the scenarios. ``translation`` and ``noise`` scale
    the hand's linear acceleration and the sensor noise (1 = as described), ``bias0_dps`` the power-on bias;
    ``rest_s`` is the rest at the start (0: moving from the first sample)."""
    if scenario not in SCENARIOS:
        raise ValueError(f"unknown scenario {scenario!r}; known: {', '.join(SCENARIOS)}")
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    n = int(round(seconds * rate_hz))
    t = np.arange(n) * dt
    gate = _smooth_gate(t, rest_s)
    # angular rate in sensor axes: a few incommensurate sines per axis, random phases (rad/s), taken at the
    # middle of each sample interval: sample i is the rate over (t[i-1], t[i]], as a gyro's is, and the
    # orientation at t[i] is q[i-1] ⊗ exp(½ w[i] dt), the order in which a filter applies gyro then accelerometer
    tm = t - 0.5 * dt
    w = np.zeros((n, 3))
    for k in range(3):
        for amp_dps, f_hz in ((60.0, 0.13 + 0.05 * k), (35.0, 0.41 + 0.07 * k), (15.0, 1.1 + 0.2 * k)):
            w[:, k] += amp_dps * DEG * np.sin(2 * np.pi * f_hz * tm + rng.uniform(0, 2 * np.pi))
    w *= _smooth_gate(tm, rest_s)[:, None]
    # true orientation (start level, x axis pointing north-east)
    q = integrate_rate(w, dt, quat.from_axis_angle(np.array([0.0, 0.0, 1.0]), 0.6))
    # hand translation in the earth frame: position sines of a few cm; acceleration analytically
    acc_lin = np.zeros((n, 3))
    for k in range(3):
        for amp_m, f_hz in ((0.06, 0.7 + 0.1 * k), (0.02, 1.6 + 0.2 * k)):
            ph = rng.uniform(0, 2 * np.pi)
            acc_lin[:, k] -= amp_m * (2 * np.pi * f_hz) ** 2 * np.sin(2 * np.pi * f_hz * t + ph)
    acc_lin *= translation * gate[:, None]
    qc = quat.conjugate(q)
    acc = quat.rotate(qc, acc_lin + np.array([0.0, 0.0, G]))
    m_earth = earth_field()
    mag = quat.rotate(qc, np.broadcast_to(m_earth, (n, 3)))
    bias = np.broadcast_to(np.asarray(bias0_dps, float) * DEG, (n, 3)).copy()
    if scenario == "step":
        bias[t >= STEP_AT_S] += STEP_DPS * DEG
    elif scenario == "ramp":
        bias += (RAMP_DPS_PER_S * DEG) * t[:, None] * RAMP_DIR
    elif scenario == "magnet":
        mag = mag + MAGNET_UT
    gyr = w + bias + noise * rng.normal(0.0, GYRO_NOISE_DPS * DEG, (n, 3))
    acc = acc + noise * rng.normal(0.0, ACC_NOISE_M_S2, (n, 3))
    mag = mag + noise * rng.normal(0.0, MAG_NOISE_UT, (n, 3))
    return Trace(scenario, dt, gyr, acc, mag, q, bias)
