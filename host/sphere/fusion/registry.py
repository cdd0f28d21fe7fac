"""Filters by the names `sphere eval` uses, each built for one trial with its settings stated.

Ours: ``madgwick`` (NWU), ``dissertation-kf`` (NWU), ``sphere`` (ENU). Peers (optional packages):
``vqf``, ``fusion``, ``ahrs-madgwick``, ``ahrs-mahony``, ``ahrs-ekf`` (see :mod:`sphere.fusion.peers`).

Our Madgwick and KF start from the e-compass orientation of the first sample (as BROAD's own example
code starts its Madgwick and Mahony); the firmware starts from [1, 0, 0, 0], so do the classes by
default. SphereFilter initialises itself from its first samples.
"""

from __future__ import annotations

from sphere.fusion import peers
from sphere.fusion.common import ecompass
from sphere.fusion.kalman import DissertationKF
from sphere.fusion.madgwick import Madgwick
from sphere.fusion.sphere_filter import SphereFilter

#: β tuned once on all shipped BROAD trials (mean total RMSE; coarse grid 0.005…0.1, then fine around the
#: optimum in steps of 0.0002–0.0005); see host/docs/fusion.md
TUNED_MADGWICK_BETA = 0.0135
#: σ_g, robust mode and threshold tuned the same way for the dissertation KF (R = 10⁻² I, P₀ = I, H = I fixed
#: by the dissertation). With "huber-norm" only the product σ_g·threshold matters on BROAD (≈ 0.018)
TUNED_KF_GYRO_NOISE = 0.5
TUNED_KF_ROBUST = "huber-norm"
TUNED_KF_THRESHOLD = 0.036
#: seconds of still data at the start used as the start-up gyro calibration for madgwick and the KF
STARTUP_BIAS_S = 1.0

OURS = ("madgwick", "dissertation-kf", "sphere")
PEERS = tuple(peers.PEERS)
ALL = OURS + PEERS


def startup_gyro_bias(gyr_rad_s, dt_s: float, seconds: float = STARTUP_BIAS_S, max_std_rad_s: float = 0.02):
    """Mean gyro over the first ``seconds`` if the sensor was still then (the device's start-up gyro
    calibration); zeros otherwise."""
    import numpy as np

    n = max(1, int(round(seconds / dt_s)))
    g = np.asarray(gyr_rad_s, dtype=float)[:n]
    if len(g) < n or np.any(g.std(axis=0) > max_std_rad_s):
        return (0.0, 0.0, 0.0)
    return tuple(g.mean(axis=0).tolist())


def make(name: str, dt_s: float, first_acc=None, first_mag=None, gyro_bias_rad_s=(0.0, 0.0, 0.0), **overrides):
    """A fresh filter called ``name`` for a stream with step ``dt_s``; first samples give the initial state.

    ``gyro_bias_rad_s`` (our Madgwick and KF only) is the start-up gyro calibration the device would apply.
    """
    q0 = (1.0, 0.0, 0.0, 0.0)
    if first_acc is not None:
        q0 = ecompass(*map(float, first_acc), *(map(float, first_mag) if first_mag is not None else (0.0, 0.0, 0.0)),
                      frame="NWU")
    if name == "madgwick":
        f = Madgwick(beta=overrides.get("beta", TUNED_MADGWICK_BETA), q0=q0, gyro_bias_rad_s=gyro_bias_rad_s)
    elif name == "dissertation-kf":
        f = DissertationKF(gyro_noise_rad_s=overrides.get("gyro_noise_rad_s", TUNED_KF_GYRO_NOISE),
                           robust=overrides.get("robust", TUNED_KF_ROBUST),
                           threshold=overrides.get("threshold", TUNED_KF_THRESHOLD),
                           measurement=overrides.get("measurement", "compensated"),
                           q0=q0, gyro_bias_rad_s=gyro_bias_rad_s)
    elif name == "sphere":
        f = SphereFilter(**overrides)
    elif name in peers.PEERS:
        f = peers.PEERS[name](dt_s)
    else:
        raise KeyError(f"unknown filter {name!r}; known: {', '.join(ALL)}")
    return f


def settings(name: str, f) -> dict:
    s = dict(f.settings)
    if name in ("madgwick", "dissertation-kf"):
        s["initial"] = "e-compass of the first sample (BROAD example code's choice)"
        s["gyro_bias"] = f"start-up calibration: mean of the first {STARTUP_BIAS_S:g} s if still"
    return s
