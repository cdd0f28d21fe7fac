"""Madgwick's gradient-descent MARG filter in double precision: the reference for the firmware.

This module is the *definition* the firmware's fixed-point filter follows (host/docs/fusion.md,
"Madgwick: the exact algorithm"), so that a recorded stream can be checked sample by sample.

Earth frame: **NWU** (x = horizontal magnetic north, y = west, z = up). ``quat`` is sensor-to-earth,
``[w, x, y, z]``: a vector measured in the sensor frame is ``q ⊗ v ⊗ q*`` in the earth frame.

One update with gyroscope ω (rad/s, calibrated: ``gyro_bias_rad_s`` is subtracted first, zero by
default), accelerometer a, magnetometer m (any units; both are normalised) and step dt (s), all on the
previous estimate q = [q0, q1, q2, q3] (Madgwick 2010; seed digest §4, eq. 66–82):

1. Rate from the gyroscope: q̇_ω = ½ q ⊗ [0, ωx, ωy, ωz].
2. If the sample's accelerometer is valid (``acc_valid``) and not all zero:
   a. â = a/‖a‖.
   b. If a magnetometer sample is present, valid (``mag_valid``) and not all zero (MARG step):
      m̂ = m/‖m‖; h = q ⊗ [0, m̂] ⊗ q*; b = [0, bx, 0, bz] with bx = √(hx² + hy²), bz = hz
      (magnetic distortion compensation); f = [f_g; f_b] (eq. 74 and 76):
        f_g = [2(q1q3 − q0q2) − âx, 2(q0q1 + q2q3) − ây, 2(½ − q1² − q2²) − âz]
        f_b = [2bx(½ − q2² − q3²) + 2bz(q1q3 − q0q2) − m̂x,
               2bx(q1q2 − q0q3)   + 2bz(q0q1 + q2q3) − m̂y,
               2bx(q0q2 + q1q3)   + 2bz(½ − q1² − q2²) − m̂z]
      ∇f = J_gᵀ f_g + J_bᵀ f_b with J_g, J_b the Jacobians of f_g, f_b with respect to q (eq. 75, 77;
      b is held constant while differentiating).
      Otherwise (IMU step): ∇f = J_gᵀ f_g.
   c. If ‖∇f‖ > 0: q̇ = q̇_ω − β ∇f/‖∇f‖, else q̇ = q̇_ω.
   Otherwise q̇ = q̇_ω (gyro only; the firmware uses ``acc_valid = False`` while a tap is in progress).
3. q ← q + q̇·dt, then q ← q/‖q‖.

Initial state q = [1, 0, 0, 0] unless another is given.
"""

from __future__ import annotations

import math

import numpy as np

from sphere.fusion.common import batch_inputs
from sphere.settings import Param

EARTH_FRAME = "NWU"
DEFAULT_BETA = 0.041  # Madgwick's published default (rad/s); eval uses the β `sphere eval --cv` chose (registry)


def madgwick_step(q, gx, gy, gz, ax, ay, az, mx, my, mz, dt, beta, acc_valid=True, mag_valid=True):
    """One Madgwick update on plain floats; returns the new (q0, q1, q2, q3). ``mx`` None = no magnetometer."""
    q0, q1, q2, q3 = q
    # 1. rate of change from the gyroscope: ½ q ⊗ [0, ω]
    d0 = 0.5 * (-q1 * gx - q2 * gy - q3 * gz)
    d1 = 0.5 * (q0 * gx + q2 * gz - q3 * gy)
    d2 = 0.5 * (q0 * gy - q1 * gz + q3 * gx)
    d3 = 0.5 * (q0 * gz + q1 * gy - q2 * gx)

    if acc_valid and not (ax == 0.0 and ay == 0.0 and az == 0.0):
        n = 1.0 / math.sqrt(ax * ax + ay * ay + az * az)
        ax *= n
        ay *= n
        az *= n
        # gravity objective (eq. 74)
        fg0 = 2.0 * (q1 * q3 - q0 * q2) - ax
        fg1 = 2.0 * (q0 * q1 + q2 * q3) - ay
        fg2 = 2.0 * (0.5 - q1 * q1 - q2 * q2) - az
        # J_gᵀ f_g (eq. 75): J_g = [[-2q2, 2q3, -2q0, 2q1], [2q1, 2q0, 2q3, 2q2], [0, -4q1, -4q2, 0]]
        s0 = -2.0 * q2 * fg0 + 2.0 * q1 * fg1
        s1 = 2.0 * q3 * fg0 + 2.0 * q0 * fg1 - 4.0 * q1 * fg2
        s2 = -2.0 * q0 * fg0 + 2.0 * q3 * fg1 - 4.0 * q2 * fg2
        s3 = 2.0 * q1 * fg0 + 2.0 * q2 * fg1
        if mag_valid and mx is not None and not (mx == 0.0 and my == 0.0 and mz == 0.0):
            n = 1.0 / math.sqrt(mx * mx + my * my + mz * mz)
            mx *= n
            my *= n
            mz *= n
            # h = q ⊗ [0, m] ⊗ q*  (field in the earth frame)
            hx = 2.0 * (mx * (0.5 - q2 * q2 - q3 * q3) + my * (q1 * q2 - q0 * q3) + mz * (q1 * q3 + q0 * q2))
            hy = 2.0 * (mx * (q1 * q2 + q0 * q3) + my * (0.5 - q1 * q1 - q3 * q3) + mz * (q2 * q3 - q0 * q1))
            hz = 2.0 * (mx * (q1 * q3 - q0 * q2) + my * (q2 * q3 + q0 * q1) + mz * (0.5 - q1 * q1 - q2 * q2))
            bx = math.sqrt(hx * hx + hy * hy)
            bz = hz
            # magnetic objective (eq. 76)
            fb0 = 2.0 * bx * (0.5 - q2 * q2 - q3 * q3) + 2.0 * bz * (q1 * q3 - q0 * q2) - mx
            fb1 = 2.0 * bx * (q1 * q2 - q0 * q3) + 2.0 * bz * (q0 * q1 + q2 * q3) - my
            fb2 = 2.0 * bx * (q0 * q2 + q1 * q3) + 2.0 * bz * (0.5 - q1 * q1 - q2 * q2) - mz
            # J_bᵀ f_b (eq. 77):
            # J_b = [[-2bz q2,          2bz q3,          -4bx q2 - 2bz q0, -4bx q3 + 2bz q1],
            #        [-2bx q3 + 2bz q1, 2bx q2 + 2bz q0,  2bx q1 + 2bz q3,  -2bx q0 + 2bz q2],
            #        [ 2bx q2,          2bx q3 - 4bz q1,  2bx q0 - 4bz q2,   2bx q1]]
            s0 += -2.0 * bz * q2 * fb0 + (-2.0 * bx * q3 + 2.0 * bz * q1) * fb1 + 2.0 * bx * q2 * fb2
            s1 += 2.0 * bz * q3 * fb0 + (2.0 * bx * q2 + 2.0 * bz * q0) * fb1 + (2.0 * bx * q3 - 4.0 * bz * q1) * fb2
            s2 += ((-4.0 * bx * q2 - 2.0 * bz * q0) * fb0 + (2.0 * bx * q1 + 2.0 * bz * q3) * fb1
                   + (2.0 * bx * q0 - 4.0 * bz * q2) * fb2)
            s3 += (-4.0 * bx * q3 + 2.0 * bz * q1) * fb0 + (-2.0 * bx * q0 + 2.0 * bz * q2) * fb1 + 2.0 * bx * q1 * fb2
        ns = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2 + s3 * s3)
        if ns > 0.0:
            ns = beta / ns
            d0 -= ns * s0
            d1 -= ns * s1
            d2 -= ns * s2
            d3 -= ns * s3

    q0 += d0 * dt
    q1 += d1 * dt
    q2 += d2 * dt
    q3 += d3 * dt
    n = 1.0 / math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    return (q0 * n, q1 * n, q2 * n, q3 * n)


class Madgwick:
    """Madgwick MARG/IMU filter, double precision, earth frame NWU (see the module docstring).

    ``update(gyr_rad_s, acc_m_s2, mag_uT, dt_s)`` takes one sample (``mag_uT=None``: no magnetometer);
    ``update_batch`` runs the same per-sample code over arrays.
    """

    earth_frame = EARTH_FRAME
    NAME = "madgwick"
    #: β's default is the grid point `sphere eval --cv` picks on all shipped BROAD trials (host/docs/fusion.md)
    PARAMS = {"beta": Param(0.0135, "rad/s", 0.0, 2.0, "gain β: how fast the accelerometer and magnetometer "
                                                        "correct the gyro's orientation")}
    GRID = {"beta": (0.005, 0.0075, 0.01, 0.0135, 0.02, 0.03, 0.05)}
    STARTUP_BIAS = True  # gets the device's start-up gyro calibration and the e-compass initial orientation
    LIVE = True  # the daemon can run it (per-sample update with acc_valid / mag_valid)

    @classmethod
    def from_settings(cls, s, dt_s=None, q0=(1.0, 0.0, 0.0, 0.0), gyro_bias_rad_s=(0.0, 0.0, 0.0)):
        return cls(q0=q0, gyro_bias_rad_s=gyro_bias_rad_s, **s.as_dict())

    def __init__(self, beta: float = DEFAULT_BETA, q0=(1.0, 0.0, 0.0, 0.0), gyro_bias_rad_s=(0.0, 0.0, 0.0)):
        self.beta = float(beta)
        #: subtracted from every gyro sample before the step (the device's calibrated bias; zero by default)
        self.gyro_bias = tuple(float(v) for v in gyro_bias_rad_s)
        self._q = tuple(float(v) for v in q0)

    @property
    def quat(self) -> np.ndarray:
        return np.array(self._q)

    @quat.setter
    def quat(self, q) -> None:
        q = [float(v) for v in q]
        n = math.sqrt(sum(v * v for v in q))
        self._q = tuple(v / n for v in q)

    @property
    def settings(self) -> dict:
        return {"beta": self.beta, "gyro_bias_rad_s": list(self.gyro_bias), "earth_frame": EARTH_FRAME}

    def update(self, gyr_rad_s, acc_m_s2, mag_uT, dt_s: float, *, acc_valid: bool = True, mag_valid: bool = True):
        gx, gy, gz = (float(v) - b for v, b in zip(gyr_rad_s, self.gyro_bias))
        ax, ay, az = (float(v) for v in acc_m_s2)
        if mag_uT is None:
            mx = my = mz = None
        else:
            mx, my, mz = (float(v) for v in mag_uT)
        self._q = madgwick_step(self._q, gx, gy, gz, ax, ay, az, mx, my, mz, float(dt_s), self.beta,
                                acc_valid, mag_valid)
        return self._q

    def update_batch(self, gyr, acc, mag, dt_s: float, *, acc_valid=None, mag_valid=None) -> np.ndarray:
        """Run :meth:`update`'s code path over (N, 3) arrays; returns (N, 4). ``mag`` may be None."""
        gyr, acc, magl, av, mv = batch_inputs(np.asarray(gyr, dtype=float) - np.asarray(self.gyro_bias), acc, mag,
                                              acc_valid, mag_valid)
        n = len(gyr)
        out = np.empty((n, 4))
        q = self._q
        beta = self.beta
        dt = float(dt_s)
        step = madgwick_step
        for i in range(n):
            g = gyr[i]
            a = acc[i]
            m = magl[i]
            if m is None:
                q = step(q, g[0], g[1], g[2], a[0], a[1], a[2], None, None, None, dt, beta, av[i], mv[i])
            else:
                q = step(q, g[0], g[1], g[2], a[0], a[1], a[2], m[0], m[1], m[2], dt, beta, av[i], mv[i])
            out[i] = q
        self._q = q
        return out
