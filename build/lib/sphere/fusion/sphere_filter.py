"""SphereFilter: our orientation filter for the sphere (earth frame **ENU**, quat sensor-to-ENU).

Built to handle what plain Madgwick and the dissertation KF do not: gyro bias that changes, rest
phases, taps and vibration, and magnetic disturbance. Plain Python floats, no numpy in the hot path,
so one update costs a few tens of microseconds (measured by ``sphere eval``).

The estimate is split into three parts, q = R_z(δ) ⊗ q_inc ⊗ q_gyr (the structure VQF made popular;
Laidig & Seel 2023), each corrected by a different sensor:

1. **Strapdown** q_gyr: bias-corrected gyro ω − b integrated exactly (axis-angle step) into a frame I
   that drifts only slowly (bias residue).
2. **Inclination** q_inc (I → E′): the accelerometer is rotated into I and low-pass filtered there
   (second order: two first-order stages of ``tau_acc_s``/2, so a 1.5 Hz hand motion is attenuated
   ~400×, not ~40× as by one stage). Linear accelerations, taps and vibration have zero mean in a frame that
   does not rotate with the hand, so they average out while gravity stays; q_inc is then set so the
   filtered vector points up. ``acc_valid=False`` (a tap in progress) skips the sample.
3. **Heading** δ about the vertical: from the magnetometer rotated into E′, the azimuth of its horizontal
   part is pulled to north (+y) with time constant ``tau_mag_s``, but only while the field looks like the
   earth's: norm within ``mag_norm_th`` (relative) and dip within ``mag_dip_th_deg`` of a reference learned
   while undisturbed. While disturbed, heading is held on the gyro. A new field is accepted as the
   reference after ``mag_new_time_s`` of consistent readings while rotating (e.g. after moving to
   another room); a field whose norm keeps changing as the sphere turns (a magnet on the sphere) never is.

Gyro bias b: a small Kalman filter (state b, covariance P, 3×3) run every ``bias_step_s``, from the first
sample on. Its prediction adds process noise (``bias_sigma_init_dps``² per ``bias_forget_s``, so a changing
bias is followed); its measurement is, at **rest** (gyro and accelerometer steady for ``rest_min_s``), the
low-passed gyro itself (noise ``bias_sigma_rest_dps``), and in **motion** the inclination correction's rate:
a bias error e turns frame I at −R·e (R the sensor → E′ rotation), the accelerometer low-pass follows with
its lag, and q_inc's correction undoes the horizontal part of it. So the measurement model uses the same
second-order low-pass on R and on R·b as on the accelerometer (the lag-matched model VQF introduced,
Laidig & Seel 2023, §3.5): correction rate c ≈ LP(R·b) − LP(R)·b_true, horizontal rows only (noise
``bias_sigma_motion_dps``, the rate's noise over 1 s); the vertical component becomes observable as the
sensor turns. With ``bias_mag`` the **magnetometer** adds two rows while the field is accepted (``_mag_rows``):
the field's direction in E′ turns as E′ does, so its rotation, on the two axes across the field, equals the drift
Φ·b_true − Ψ plus the corrections q_inc applied: exactly, with no lag-matching needed and nothing of the hand's
linear acceleration in it (the tilt that acceleration causes is in the known corrections). Those rows see the
vertical component (heading) the tilt rows cannot. Their noise is σ_motion² plus what the field's own noise gives
them (measured from consecutive steps); a step whose rows a bias within P cannot explain (χ² test at
``bias_change_alpha``: a magnet riding on the sensor that the disturbance test let through) is not used. The update
is the Kalman update in information form, so any number of rows costs one 3×3 inverse. b is clipped to
``bias_clip_dps``, each diagonal of P to its initial value.

That prior (σ_motion) makes the filter slow in motion on purpose: real hand motion leaves bias-like errors in
the measurement (lever arm, scale factors) that a fast filter would follow. A bias that really changes (a step)
is caught by a **change test** on the same measurements (``_change_test``, the magnetometer's rows weighted by
their noise): an F-test of a constant bias fitted over K = ``bias_change_blocks`` one-second blocks against b,
significant at ``bias_change_alpha`` in two consecutive windows that agree. Then b restarts from the latest
window's least-squares fit of the bias itself, with the covariance that fit has (not P₀, which threw the window's data away), and for 2K blocks the filter uses the
measurement noise that fit showed (no process noise), so it settles in seconds. Its threshold is a
quantile of the F distribution, not a tuned value.

The free settings (``tau_acc_s``, ``bias_sigma_motion_dps``, ``bias_forget_s``) are the ones ``sphere eval --cv``
chose, leave one trial out (host/docs/fusion.md); the rest are VQF's published defaults where VQF has one.
"""

from __future__ import annotations

import math
from math import atan2 as _atan2, cos as _cos, sin as _sin, sqrt as _sqrt

import numpy as np

from sphere.fusion.common import batch_inputs

EARTH_FRAME = "ENU"


def _qmul(p, q):
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q
    return (p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
            p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
            p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0)


def _rot(q, x, y, z):
    """q ⊗ [0, v] ⊗ q* for a unit q."""
    q0, q1, q2, q3 = q
    return (2.0 * (x * (0.5 - q2 * q2 - q3 * q3) + y * (q1 * q2 - q0 * q3) + z * (q1 * q3 + q0 * q2)),
            2.0 * (x * (q1 * q2 + q0 * q3) + y * (0.5 - q1 * q1 - q3 * q3) + z * (q2 * q3 - q0 * q1)),
            2.0 * (x * (q1 * q3 - q0 * q2) + y * (q2 * q3 + q0 * q1) + z * (0.5 - q1 * q1 - q2 * q2)))


def _norm4(q):
    n = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] * n, q[1] * n, q[2] * n, q[3] * n)


_PI = math.pi
_TWO_PI = 2.0 * math.pi


def _wrap(a):
    return (a + _PI) % _TWO_PI - _PI


DEFAULTS = dict(
    tau_acc_s=3.0,
    tau_mag_s=15.0,
    mag_norm_th=0.05,
    mag_dip_th_deg=5.0,
    mag_ref_tau_s=20.0,
    mag_new_time_s=20.0,
    mag_new_min_gyr_dps=20.0,
    rest_min_s=1.5,
    rest_tau_s=0.5,
    rest_th_gyr_dps=2.0,
    rest_th_acc_m_s2=0.5,
    bias_step_s=0.05,
    bias_sigma_init_dps=0.5,
    bias_forget_s=100.0,
    bias_sigma_rest_dps=0.03,
    bias_sigma_motion_dps=0.3,
    bias_lp_s=1.0,
    bias_clip_dps=2.0,
    bias_change_test=True,
    bias_change_block_s=1.0,
    bias_change_blocks=6,
    bias_change_alpha=1e-3,
    bias_mag=True,  # the magnetometer's rows in the bias measurement (see _mag_rows)
)


class SphereFilter:
    """Our best orientation filter (ENU). See the module docstring for the method; settings in ``DEFAULTS``."""

    earth_frame = EARTH_FRAME
    #: ``update_batch(..., diagnostics=True)`` returns the per-sample rest flag, bias and disturbance flag
    diagnostics = ("rest", "bias_rad_s", "mag_disturbed")

    def __init__(self, **settings):
        unknown = set(settings) - set(DEFAULTS)
        if unknown:
            raise TypeError(f"unknown SphereFilter settings: {', '.join(sorted(unknown))}")
        self.cfg = dict(DEFAULTS, **settings)
        self._ct_k = int(self.cfg["bias_change_blocks"])
        # the change test's threshold: the F(3, 2K − 3) quantile at 1 − α (needs K ≥ 3)
        self._ct_f = _f_quantile(3, 2 * self._ct_k - 3, 1.0 - self.cfg["bias_change_alpha"]) if self._ct_k >= 3 else None
        self.reset()

    def reset(self) -> None:
        self.q_gyr = (1.0, 0.0, 0.0, 0.0)
        self.q_inc = (1.0, 0.0, 0.0, 0.0)
        self.delta = 0.0
        self.bias = [0.0, 0.0, 0.0]
        p0 = math.radians(self.cfg["bias_sigma_init_dps"]) ** 2
        self.bias_P = [[p0, 0.0, 0.0], [0.0, p0, 0.0], [0.0, 0.0, p0]]
        self.acc_lp1 = [0.0, 0.0, 0.0]
        self.acc_lp = [0.0, 0.0, 0.0]
        self.n_acc = 0
        self.n_mag = 0
        self.mag_ref = None  # (norm, dip)
        self.mag_cand = None
        self.mag_cand_time = 0.0
        self.mag_disturbed = False
        self.rest_gyr = [0.0, 0.0, 0.0]
        self.rest_acc = [0.0, 0.0, 0.0]
        self.rest_time = 0.0
        self.at_rest = False
        self._rest_init = False
        self._dt = None
        # bias estimation (see _bias_step): integrals of R's two horizontal rows, of R·b and of the
        # correction angles; the first two low-passed as the accelerometer is, all by the third stage
        self._cx = self._cy = 0.0
        self._nb = 0
        self._n_bias = 0
        self._int = [0.0] * 10
        self._blp1 = [0.0] * 8
        self._blp = [0.0] * 8
        self._blp3 = [0.0] * 10
        # the magnetometer rows (see _bias_step): the accepted field's direction in E′ summed over the step, and
        # the chain of 1 s low-passes over R's three rows, R·b, the corrections and that direction
        self._msum = [0.0, 0.0, 0.0]
        self._mcount = 0
        self._m_new = False
        self._int2 = [0.0] * 4  # ∫R's third row, ∫(R·b)_z
        self._mlp = [0.0] * 15
        self._m_n = 0
        self._m_u = (0.0, 0.0, 1.0)
        self._m_prev_end = None
        self._m_v = 0.0
        self._m_nv = 0
        # the change test (see _change_test): sums over the current block, the finished blocks' means
        self._ct_sum = [0.0] * 8
        self._ct_n = 0
        self._ct_msum = [0.0] * 8
        self._ct_mn = 0
        self._ct_blocks = []
        #: bias changes the change test has detected (and applied)
        self.bias_changes = 0
        self._track_w = 0.0  # after a detected change: the measurement noise the blocks showed (per step) ...
        self._track_left = 0  # ... for this many more bias steps
        #: a bias step is due and was deferred (``update(..., defer_bias=True)``); ``run_deferred`` runs it
        self.bias_pending = False

    @property
    def settings(self) -> dict:
        return dict(self.cfg, earth_frame=EARTH_FRAME)

    @property
    def quat(self) -> np.ndarray:
        return np.array(self._quat())

    def _quat(self):
        # _norm4(_qmul(qz, _qmul(q_inc, q_gyr))) with qz = (cos h, 0, 0, sin h), written out (every sample)
        h = 0.5 * self.delta
        p0, p1, p2, p3 = self.q_inc
        q0, q1, q2, q3 = self.q_gyr
        r0 = p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3
        r1 = p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2
        r2 = p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1
        r3 = p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0
        p0, p3 = _cos(h), _sin(h)
        q0 = p0 * r0 - 0.0 * r1 - 0.0 * r2 - p3 * r3
        q1 = p0 * r1 + 0.0 * r0 + 0.0 * r3 - p3 * r2
        q2 = p0 * r2 - 0.0 * r3 + 0.0 * r0 + p3 * r1
        q3 = p0 * r3 + 0.0 * r2 - 0.0 * r1 + p3 * r0
        n = 1.0 / _sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        return (q0 * n, q1 * n, q2 * n, q3 * n)

    def _coeffs(self, dt):
        c = self.cfg
        k = lambda tau: 1.0 - math.exp(-dt / tau)  # noqa: E731
        self._dt = dt
        self._k_acc = k(0.5 * c["tau_acc_s"])  # per stage of the second-order low-pass
        self._k_mag = k(c["tau_mag_s"])
        self._k_ref = k(c["mag_ref_tau_s"])
        self._k_rest = k(c["rest_tau_s"])
        self._nb_step = max(1, int(round(c["bias_step_s"] / dt)))
        tb = self._nb_step * dt
        self._tb = tb
        self._k_blp = 1.0 - math.exp(-tb / (0.5 * c["tau_acc_s"]))
        self._k_blp3 = 1.0 - math.exp(-tb / c["bias_lp_s"]) if c["bias_lp_s"] > 0 else 1.0
        d2 = math.radians(1.0) ** 2
        self._b_p0 = c["bias_sigma_init_dps"] ** 2 * d2
        self._b_v = self._b_p0 * tb / c["bias_forget_s"]  # process noise per bias step
        self._b_wrest = c["bias_sigma_rest_dps"] ** 2 * d2
        # the sigma is for the rate over 1 s; the mean over tb is noisier by 1/tb
        self._b_wmot = c["bias_sigma_motion_dps"] ** 2 * d2 / tb if c["bias_sigma_motion_dps"] > 0 else 0.0
        self._bias_clip = math.radians(c["bias_clip_dps"])
        self._mag_gate = -2.0 * math.log(c["bias_change_alpha"])  # the χ²(2) quantile at 1 − α
        self._ct_block = max(1, int(round(c["bias_change_block_s"] / tb)))
        self._rest_gyr2 = math.radians(c["rest_th_gyr_dps"]) ** 2
        self._rest_acc2 = c["rest_th_acc_m_s2"] ** 2
        self._new_min_gyr2 = math.radians(c["mag_new_min_gyr_dps"]) ** 2
        self._dip_th = math.radians(c["mag_dip_th_deg"])
        self._norm_th = c["mag_norm_th"]
        self._use_mag = bool(c["bias_mag"])
        self._lp_s = c["bias_lp_s"]
        self._ct_on = self._ct_f is not None and bool(c["bias_change_test"])
        self._rest_min = c["rest_min_s"]

    def update(self, gyr_rad_s, acc_m_s2, mag_uT, dt_s: float, *, acc_valid: bool = True, mag_valid: bool = True,
               defer_bias: bool = False):
        """One sample; returns the orientation (a tuple of floats, sensor → ENU).

        ``defer_bias=True`` leaves the bias step that falls due on this sample (every ``bias_step_s``, the one
        costly part) pending, so a live caller can emit the sample's orientation first and then call
        :meth:`run_deferred`. The step does not change this sample's orientation, only the next samples'; a
        step still pending when the next ``update`` comes is run first thing there. Either way the results are
        bit-identical to ``update`` without deferring."""
        gx, gy, gz = gyr_rad_s
        ax, ay, az = acc_m_s2
        m = None if (mag_uT is None or not mag_valid) else mag_uT
        self._step(float(gx), float(gy), float(gz), float(ax), float(ay), float(az), m, float(dt_s), acc_valid,
                   defer_bias)
        return self._quat()

    def run_deferred(self) -> bool:
        """Run the bias step an ``update(..., defer_bias=True)`` left pending; True if there was one."""
        if self.bias_pending:
            self._bias_step()
            return True
        return False

    def update_batch(self, gyr, acc, mag, dt_s: float, *, acc_valid=None, mag_valid=None, diagnostics: bool = False):
        """Run the per-sample step over (N, 3) arrays; returns (N, 4). ``mag`` may be None.

        With ``diagnostics=True`` returns a dict instead (as VQF's batch API does): ``quat`` (N, 4), ``rest``
        (N,) bool, ``bias_rad_s`` (N, 3) and ``mag_disturbed`` (N,) bool, each after the sample's step."""
        gyr, acc, magl, av, mv = batch_inputs(gyr, acc, mag, acc_valid, mag_valid)
        n = len(gyr)
        out = np.empty((n, 4))
        dt = float(dt_s)
        step = self._step
        quat = self._quat
        if not diagnostics:
            for i in range(n):
                g = gyr[i]
                a = acc[i]
                step(g[0], g[1], g[2], a[0], a[1], a[2], magl[i] if mv[i] else None, dt, av[i])
                out[i] = quat()
            return out
        rest = np.zeros(n, bool)
        dist = np.zeros(n, bool)
        bias = np.empty((n, 3))
        for i in range(n):
            g = gyr[i]
            a = acc[i]
            step(g[0], g[1], g[2], a[0], a[1], a[2], magl[i] if mv[i] else None, dt, av[i])
            out[i] = quat()
            rest[i] = self.at_rest
            dist[i] = self.mag_disturbed
            bias[i] = self.bias
        return {"quat": out, "rest": rest, "bias_rad_s": bias, "mag_disturbed": dist}

    # -- the filter ---------------------------------------------------------------------------------
    def _step(self, gx, gy, gz, ax, ay, az, m, dt, acc_valid, defer_bias=False):
        # the quaternion products, rotations and normalisations of _qmul, _rot and _norm4 are written out here
        # (the same operations in the same order: the same bits), as this runs at every sample
        if self.bias_pending:  # deferred by the previous update and not run since: its state is still as it was
            self._bias_step()
        if self._dt is None or abs(dt - self._dt) > 1e-3 * self._dt:
            self._coeffs(dt)  # a live link's intervals jitter by a few µs: the gains follow changes over 0.1 %
        # rest detection (VQF's): gyro and accelerometer steady for rest_min_s
        rg, ra = self.rest_gyr, self.rest_acc
        if not self._rest_init:
            rg[:] = [gx, gy, gz]
            ra[:] = [ax, ay, az]
            self._rest_init = True
        k = self._k_rest
        rg[0] += k * (gx - rg[0])
        rg[1] += k * (gy - rg[1])
        rg[2] += k * (gz - rg[2])
        ra[0] += k * (ax - ra[0])
        ra[1] += k * (ay - ra[1])
        ra[2] += k * (az - ra[2])
        dg = (gx - rg[0]) ** 2 + (gy - rg[1]) ** 2 + (gz - rg[2]) ** 2
        da = (ax - ra[0]) ** 2 + (ay - ra[1]) ** 2 + (az - ra[2]) ** 2
        lg = rg[0] * rg[0] + rg[1] * rg[1] + rg[2] * rg[2]
        if dg < self._rest_gyr2 and da < self._rest_acc2 and lg < self._rest_gyr2:
            self.rest_time += dt
        else:
            self.rest_time = 0.0
        self.at_rest = self.rest_time >= self._rest_min
        b = self.bias
        wx, wy, wz = gx - b[0], gy - b[1], gz - b[2]

        # 1. strapdown: q_gyr ← q_gyr ⊗ exp(½ ω dt)
        wn = _sqrt(wx * wx + wy * wy + wz * wz)
        if wn > 1e-12:
            ang = 0.5 * wn * dt
            s = _sin(ang) / wn
            q0, q1, q2, q3 = _cos(ang), wx * s, wy * s, wz * s
            p0, p1, p2, p3 = self.q_gyr
            r0 = p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3
            r1 = p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2
            r2 = p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1
            r3 = p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0
            n = 1.0 / _sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
            self.q_gyr = (r0 * n, r1 * n, r2 * n, r3 * n)

        # 2. inclination from the accelerometer low-passed in frame I
        if acc_valid and (ax or ay or az):
            q0, q1, q2, q3 = self.q_gyr
            ix = 2.0 * (ax * (0.5 - q2 * q2 - q3 * q3) + ay * (q1 * q2 - q0 * q3) + az * (q1 * q3 + q0 * q2))
            iy = 2.0 * (ax * (q1 * q2 + q0 * q3) + ay * (0.5 - q1 * q1 - q3 * q3) + az * (q2 * q3 - q0 * q1))
            iz = 2.0 * (ax * (q1 * q3 - q0 * q2) + ay * (q2 * q3 + q0 * q1) + az * (0.5 - q1 * q1 - q2 * q2))
            n_acc = self.n_acc = self.n_acc + 1
            k = self._k_acc
            kn = 1.0 / n_acc
            if kn > k:
                k = kn
            # second-order low-pass: two first-order stages of τ/2 each (critically damped)
            l1 = self.acc_lp1
            l0 = l1[0] + k * (ix - l1[0])
            l1_ = l1[1] + k * (iy - l1[1])
            l2 = l1[2] + k * (iz - l1[2])
            l1[0], l1[1], l1[2] = l0, l1_, l2
            lp = self.acc_lp
            x_ = lp[0] + k * (l0 - lp[0])
            y_ = lp[1] + k * (l1_ - lp[1])
            z_ = lp[2] + k * (l2 - lp[2])
            lp[0], lp[1], lp[2] = x_, y_, z_
            q0, q1, q2, q3 = self.q_inc
            vx = 2.0 * (x_ * (0.5 - q2 * q2 - q3 * q3) + y_ * (q1 * q2 - q0 * q3) + z_ * (q1 * q3 + q0 * q2))
            vy = 2.0 * (x_ * (q1 * q2 + q0 * q3) + y_ * (0.5 - q1 * q1 - q3 * q3) + z_ * (q2 * q3 - q0 * q1))
            vz = 2.0 * (x_ * (q1 * q3 - q0 * q2) + y_ * (q2 * q3 + q0 * q1) + z_ * (0.5 - q1 * q1 - q2 * q2))
            vn = _sqrt(vx * vx + vy * vy + vz * vz)
            if vn > 0.0:
                vx, vy, vz = vx / vn, vy / vn, vz / vn
                # smallest rotation taking v to +z: axis v × z = (vy, −vx, 0)
                w = 1.0 + vz
                if w > 1e-9:
                    rn = 1.0 / _sqrt(w * w + vx * vx + vy * vy)
                    p0, p1, p2, p3 = w * rn, vy * rn, -vx * rn, 0.0
                else:
                    p0, p1, p2, p3 = 0.0, 1.0, 0.0, 0.0
                r0 = p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3
                r1 = p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2
                r2 = p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1
                r3 = p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0
                n = 1.0 / _sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
                self.q_inc = (r0 * n, r1 * n, r2 * n, r3 * n)
                if n_acc > 1:  # the first sample's alignment is not a drift
                    self._cx += 2.0 * p1
                    self._cy += 2.0 * p2

        # 3. heading from the magnetometer, with disturbance detection
        if m is not None:
            mx, my, mz = m
            mx, my, mz = float(mx), float(my), float(mz)
            if mx or my or mz:
                self._mag(mx, my, mz, gx, gy, gz, dt)

        # 4. gyro bias, every bias_step_s
        self._nb += 1
        if self._nb >= self._nb_step:
            if defer_bias:
                self.bias_pending = True
            else:
                self._bias_step()

    def _bias_step(self):
        """One step of the bias Kalman filter (see the module docstring).

        Small-angle model: a bias error e turns frame I by θ(t) = −∫R_I·e dt; the accelerometer low-pass F
        sees F[θ], and q_inc's corrections add up to C = F[∫R·e]_h (horizontal rows, E′). So with Φ = ∫R dt
        and Ψ = ∫R·b dt, each passed through the same F (the same gain schedule, including the averaging
        start): C = F[Ψ] − F[Φ]·b_true, exactly also while F is still averaging. Per step the differences
        over the step, divided by its length, are the measurement; a third low-pass stage (``bias_lp_s``)
        on both sides takes out the hand's oscillations."""
        self.bias_pending = False
        tb = self._tb
        b = self.bias
        q0, q1, q2, q3 = _qmul(self.q_inc, self.q_gyr)  # sensor → E′
        r00, r01, r02 = 1.0 - 2.0 * (q2 * q2 + q3 * q3), 2.0 * (q1 * q2 - q0 * q3), 2.0 * (q1 * q3 + q0 * q2)
        r10, r11, r12 = 2.0 * (q1 * q2 + q0 * q3), 1.0 - 2.0 * (q1 * q1 + q3 * q3), 2.0 * (q2 * q3 - q0 * q1)
        x = (r00, r01, r02, r10, r11, r12,
             r00 * b[0] + r01 * b[1] + r02 * b[2], r10 * b[0] + r11 * b[1] + r12 * b[2])
        it = self._int
        it[:8] = [a + c * tb for a, c in zip(it, x)]
        it[8] += self._cx
        it[9] += self._cy
        self._cx = self._cy = 0.0
        self._nb = 0
        self._n_bias += 1
        k = max(self._k_blp, 1.0 / self._n_bias)
        l1, lp = self._blp1, self._blp
        l1[:] = [a + k * (c - a) for a, c in zip(l1, it)]
        lp[:] = [a + k * (c - a) for a, c in zip(lp, l1)]
        k3 = self._k_blp3
        prev = self._blp3
        l3 = [a + k3 * (c - a) for a, c in zip(prev, lp)]
        l3 += (prev[8] + k3 * (it[8] - prev[8]), prev[9] + k3 * (it[9] - prev[9]))
        self._blp3 = l3
        g = 1.0 / tb
        d = [(a - c) * g for a, c in zip(l3, prev)]
        mrows = self._mag_rows(q0, q1, q2, q3, b, tb) if self._use_mag else None
        P = self.bias_P
        v, p0 = self._b_v, self._b_p0
        if self._track_left:
            v = 0.0  # after a detected change the bias is taken as constant while the data pin it down
        for i in range(3):
            P[i][i] = min(P[i][i] + v, p0)
        b0, b1, b2 = b
        if self.at_rest:
            if self._ct_n or self._ct_blocks:
                self._ct_clear()
            self._track_left = 0
            # measurement: the low-passed gyro at rest, H = I
            iw = 1.0 / self._b_wrest
            rg = self.rest_gyr
            rows = ((1.0, 0.0, 0.0, rg[0] - b0, iw), (0.0, 1.0, 0.0, rg[1] - b1, iw), (0.0, 0.0, 1.0, rg[2] - b2, iw))
        elif self._b_wmot:
            # measurement: z = ΔF[Ψ] − ΔC = ΔF[Φ]·b_true + noise (rates over the step), H = ΔF[Φ]
            H = ((d[0], d[1], d[2]), (d[3], d[4], d[5]))
            y = (d[6] - d[8] - (d[0] * b0 + d[1] * b1 + d[2] * b2),
                 d[7] - d[9] - (d[3] * b0 + d[4] * b1 + d[5] * b2))
            w = self._b_wmot
            if self._track_left:
                self._track_left -= 1
                w = self._track_w
            scale = w / self._b_wmot  # after a detected change: the noise the fit showed, for every row
            if self.n_acc * self._k_acc < 1.0:
                # the accelerometer low-pass still averages (gain 1/n > k): c is noisier by about 1/(n·k)
                w /= max(self.n_acc * self._k_acc, 1e-3) ** 2
            mag = None
            if mrows is not None:
                (g0, g1, g2), (g3, g4, g5), z0, z1, wm = mrows
                m0 = z0 - (g0 * b0 + g1 * b1 + g2 * b2)
                m1 = z1 - (g3 * b0 + g4 * b1 + g5 * b2)
                if self._mag_consistent(g0, g1, g2, g3, g4, g5, m0, m1, wm, P):
                    mag = (mrows[0], mrows[1], m0, m1, wm)
            if self._ct_on and self._change_test(H, y, mag):
                return
            iw = 1.0 / w
            rows = ((d[0], d[1], d[2], y[0], iw), (d[3], d[4], d[5], y[1], iw))
            if mag is not None:
                # the magnetometer's rows: their noise per step as the tilt rows' (σ²/tb), with σ² theirs
                iw = tb / (wm * scale)
                rows += ((g0, g1, g2, m0, iw), (g3, g4, g5, m1, iw))
        else:
            return
        # the update in information form (the same as the Kalman gain's, with one 3×3 inverse for any rows):
        # P⁺ = (P⁻¹ + Σ hᵀh / w)⁻¹, b⁺ = b + P⁺ Σ hᵀ y / w
        j00 = j01 = j02 = j11 = j12 = j22 = s0 = s1 = s2 = 0.0
        for h0, h1, h2, yy, iw in rows:
            a0, a1, a2 = h0 * iw, h1 * iw, h2 * iw
            j00 += a0 * h0
            j01 += a0 * h1
            j02 += a0 * h2
            j11 += a1 * h1
            j12 += a1 * h2
            j22 += a2 * h2
            s0 += a0 * yy
            s1 += a1 * yy
            s2 += a2 * yy
        (i00, i01, i02), (_, i11, i12), (_, _, i22) = _inv3(P)
        Pn = _inv3(((i00 + j00, i01 + j01, i02 + j02), (i01 + j01, i11 + j11, i12 + j12),
                    (i02 + j02, i12 + j12, i22 + j22)))
        clip = self._bias_clip
        for i in range(3):
            p = Pn[i]
            v_ = b[i] + p[0] * s0 + p[1] * s1 + p[2] * s2
            b[i] = clip if v_ > clip else (-clip if v_ < -clip else v_)
        self.bias_P = Pn

    def _mag_rows(self, q0, q1, q2, q3, b, tb):
        """The magnetometer's two rows of the bias measurement: (h₁, h₂, z₁, z₂, σ²) or None.

        The field's direction m in E′ turns as E′ does: a bias error turns E′ at R·e and q_inc's corrections C turn
        it back, so with α E′'s misalignment, α = Φ·b_true − Ψ + C + const (C = (Cx, Cy, 0)) and m × Δm = Δα on the
        two axes u₁, u₂ perpendicular to m: exactly for small angles, and free of the hand's linear acceleration
        (whatever tilt it causes is in C, which is known). Both sides pass through the same 1 s low-pass
        (``bias_lp_s``, averaging start); the chain starts again whenever a step had a sample without an accepted
        field (disturbed, missing) or a new field was accepted, and its rows count after a full ``bias_lp_s`` of
        accepted readings. Their noise σ² (for the rate over 1 s, as σ_motion is the tilt rows'): σ_motion² plus
        what the field's own noise gives the row (v, the noise of a step's mean direction across it, measured from
        consecutive steps, through the low-pass and the difference: 2k²v / ((2 − k) tb²))."""
        r20, r21, r22 = 2.0 * (q1 * q3 - q0 * q2), 2.0 * (q2 * q3 + q0 * q1), 1.0 - 2.0 * (q1 * q1 + q2 * q2)
        i2 = self._int2
        i2[0] += r20 * tb
        i2[1] += r21 * tb
        i2[2] += r22 * tb
        i2[3] += (r20 * b[0] + r21 * b[1] + r22 * b[2]) * tb
        it = self._int
        # Φ (three rows), Ψ − C at the step's end; paired with the field's mean over the step, they are taken at the
        # step's middle (the mean of this end and the last: the corrections swing with the hand's translation, and
        # half a step between the two sides of the model would show as a rate)
        xe = (it[0], it[1], it[2], it[3], it[4], it[5], i2[0], i2[1], i2[2], it[6] - it[8], it[7] - it[9], i2[3])
        xp = self._m_prev_end
        self._m_prev_end = xe
        ms = self._msum
        mx, my, mz = ms
        full = self._mcount == self._nb_step and not self._m_new and xp is not None
        ms[0] = ms[1] = ms[2] = 0.0
        self._mcount = 0
        self._m_new = False
        if not full:
            self._m_n = 0
            return None
        x = [0.5 * (a + c) for a, c in zip(xe, xp)]
        x += (mx, my, mz)
        un = 1.0 / _sqrt(mx * mx + my * my + mz * mz)
        ux, uy, uz = mx * un, my * un, mz * un
        n = self._m_n
        if n:
            pu = self._m_u
            dv = ((ux - pu[0]) ** 2 + (uy - pu[1]) ** 2 + (uz - pu[2]) ** 2) * 0.25
            self._m_nv += 1
            self._m_v += (dv - self._m_v) / self._m_nv
        self._m_u = (ux, uy, uz)
        n = self._m_n = n + 1
        prev = self._mlp
        if n == 1:
            self._mlp = x
            return None
        k = self._k_blp3
        if n * k < 1.0:
            k = 1.0 / n
        self._mlp = lp = [a + k * (c - a) for a, c in zip(prev, x)]
        if n * tb < self._lp_s:
            return None
        g = 1.0 / tb
        d = [(a - c) * g for a, c in zip(lp, prev)]
        mx, my, mz = lp[12], lp[13], lp[14]
        h = mx * mx + my * my
        if h <= 0.0:
            return None
        mn = 1.0 / _sqrt(h + mz * mz)
        h = _sqrt(h) * mn
        mx, my, mz = mx * mn, my * mn, mz * mn
        dx, dy, dz = d[12] * mn, d[13] * mn, d[14] * mn
        # the rotation the field shows: m × Δm (its part along m is not seen)
        wx, wy, wz = my * dz - mz * dy, mz * dx - mx * dz, mx * dy - my * dx
        # u₁ horizontal, across the field; u₂ = m × u₁
        u0, u1 = my / h, -mx / h
        v0, v1, v2 = -mz * u1, mz * u0, mx * u1 - my * u0
        k3 = self._k_blp3
        var = self._b_wmot * tb + 2.0 * k3 * k3 * self._m_v / ((2.0 - k3) * tb * tb)
        return ((u0 * d[0] + u1 * d[3], u0 * d[1] + u1 * d[4], u0 * d[2] + u1 * d[5]),
                (v0 * d[0] + v1 * d[3] + v2 * d[6], v0 * d[1] + v1 * d[4] + v2 * d[7],
                 v0 * d[2] + v1 * d[5] + v2 * d[8]),
                u0 * (wx + d[9]) + u1 * (wy + d[10]),
                v0 * (wx + d[9]) + v1 * (wy + d[10]) + v2 * (wz + d[11]),
                var)

    def _mag_consistent(self, g0, g1, g2, g3, g4, g5, y0, y1, var, P) -> bool:
        """Is the rotation the field shows one a bias within the filter's uncertainty can explain? The innovation
        (y0, y1) of the two rows h = (g0, g1, g2), (g3, g4, g5) (each a rate over the 1 s low-pass, so of noise σ²,
        not the per-step σ²/tb the update uses) against S = H P Hᵀ + σ² I: d² = yᵀ S⁻¹ y below the 1 −
        ``bias_change_alpha`` quantile of χ²(2), −2 ln α. A field that turns with the sensor (a magnet riding on it)
        while its norm and dip happen to stay within the disturbance test's bounds shows rates of several °/s and
        is not used."""
        (p00, p01, p02), (_, p11, p12), (_, _, p22) = P
        a0 = p00 * g0 + p01 * g1 + p02 * g2
        a1 = p01 * g0 + p11 * g1 + p12 * g2
        a2 = p02 * g0 + p12 * g1 + p22 * g2
        c0 = p00 * g3 + p01 * g4 + p02 * g5
        c1 = p01 * g3 + p11 * g4 + p12 * g5
        c2 = p02 * g3 + p12 * g4 + p22 * g5
        s00 = g0 * a0 + g1 * a1 + g2 * a2 + var
        s01 = g3 * a0 + g4 * a1 + g5 * a2
        s11 = g3 * c0 + g4 * c1 + g5 * c2 + var
        return (s11 * y0 * y0 - 2.0 * s01 * y0 * y1 + s00 * y1 * y1) < self._mag_gate * (s00 * s11 - s01 * s01)

    def _ct_clear(self):
        self._ct_sum[:] = [0.0] * 8
        self._ct_msum[:] = [0.0] * 8
        self._ct_n = self._ct_mn = 0
        self._ct_blocks.clear()

    def _change_test(self, H, y, mag=None) -> bool:
        """Has the bias changed? A test on the motion measurements: the tilt rows (H, y) and the magnetometer's rows
        ``mag`` = (h₁, h₂, y₁, y₂, σ²) when it has them, y the innovations (z − H·b); the magnetometer's rows are
        scaled by σ_motion/σ (weighted least squares: every row then has the tilt rows' noise).

        Rows are averaged over blocks of ``bias_change_block_s`` (1 s: the hand's oscillations and the third
        low-pass stage make neighbouring steps strongly correlated, the block means much less so); a block has the
        magnetometer's rows only if every one of its steps had them. Over a window of K = ``bias_change_blocks``
        blocks (n rows) one constant bias is fitted by least squares to the measurements' bias-like part
        z = y + H·b (b as it was at each block's end: b moves during a window, so z, not y, is what is constant when
        the bias is) and tested against b now with the regression's F statistic, (explained / 3) / (residual /
        (n − 3)), whose noise variance comes from the fit's own residuals, so the threshold is the 1 −
        ``bias_change_alpha`` quantile of F(3, n − 3), a statistic of the noise, not a tuned value. A bias change
        must show in two consecutive windows (the last 2K blocks), each significant against b at its end, and the
        two fits of the bias must agree (the same quantile on their difference): real hand motion produces
        bias-like errors too (on BROAD's fast rotations, flipping every few seconds), a changed bias stays. What
        follows a change is described below; the blocks start afresh. Returns True when it did so (the Kalman
        update of this step is skipped)."""
        s = self._ct_sum
        s[0] += y[0]
        s[1] += y[1]
        (h0, h1, h2), (h3, h4, h5) = H
        s[2] += h0
        s[3] += h1
        s[4] += h2
        s[5] += h3
        s[6] += h4
        s[7] += h5
        if mag is not None:
            # weighted least squares: the magnetometer's rows scaled to the tilt rows' noise
            (h0, h1, h2), (h3, h4, h5), y0, y1, var = mag
            c = _sqrt(self._b_wmot * self._tb / var)
            sm = self._ct_msum
            sm[0] += c * y0
            sm[1] += c * h0
            sm[2] += c * h1
            sm[3] += c * h2
            sm[4] += c * y1
            sm[5] += c * h3
            sm[6] += c * h4
            sm[7] += c * h5
            self._ct_mn += 1
        self._ct_n += 1
        if self._ct_n < self._ct_block:
            return False
        blocks = self._ct_blocks
        g = 1.0 / self._ct_n
        b = self.bias
        m = [v * g for v in s]
        rows = [(m[0], m[2], m[3], m[4]), (m[1], m[5], m[6], m[7])]
        if self._ct_mn == self._ct_n:
            m = [v * g for v in self._ct_msum]
            rows += [(m[0], m[1], m[2], m[3]), (m[4], m[5], m[6], m[7])]
        # z = y + H·b at the block's end
        blocks.append(([(yy + hh0 * b[0] + hh1 * b[1] + hh2 * b[2], hh0, hh1, hh2) for yy, hh0, hh1, hh2 in rows],
                       list(b)))
        s[:] = [0.0] * 8
        self._ct_msum[:] = [0.0] * 8
        self._ct_n = self._ct_mn = 0
        k = self._ct_k
        if len(blocks) > 2 * k:
            del blocks[0]
        if len(blocks) < 2 * k:
            return False
        alpha = 1.0 - self.cfg["bias_change_alpha"]
        cur_rows = [r for blk in blocks[k:] for r in blk[0]]
        cur = _fit(cur_rows, about=b)
        if cur is None or cur[3] < _f_quantile(3, len(cur_rows) - 3, alpha):
            return False
        prev_rows = [r for blk in blocks[:k] for r in blk[0]]
        prev = _fit(prev_rows, about=blocks[k - 1][1])
        if prev is None or prev[3] < _f_quantile(3, len(prev_rows) - 3, alpha):
            return False
        # the two windows' fits of the bias itself, each with covariance var·A⁻¹
        bp, bc = prev[0], cur[0]
        vp = [[prev[2] * a for a in row] for row in prev[1]]
        vc = [[cur[2] * a for a in row] for row in cur[1]]
        d = [bc[i] - bp[i] for i in range(3)]
        si = _inv3([[vp[i][j] + vc[i][j] for j in range(3)] for i in range(3)])
        if sum(d[i] * si[i][j] * d[j] for i in range(3) for j in range(3)) / 3.0 > _f_quantile(
                3, min(len(cur_rows), len(prev_rows)) - 3, alpha):
            return False  # both significant, but not the same bias: motion, not a change
        # the change: b starts again from the latest window's own fit of the bias itself (not "b now + a constant
        # error e": b moved during the window, so e was not constant), with the covariance that fit has (var·A⁻¹, the
        # information of the window's K s of data, where P₀ threw it away), and for the next 2K blocks the Kalman
        # filter takes the measurement noise that fit showed (its residual variance of 1 s means, per step as
        # _b_wmot is) and no process noise: the new, constant bias is pinned down at the rate the data allow, not at
        # the slow rate the prior σ_motion sets
        bw, ai, var, _ = cur
        clip = self._bias_clip
        for i in range(3):
            v_ = bw[i]
            b[i] = clip if v_ > clip else (-clip if v_ < -clip else v_)
        self.bias_P = [[var * a for a in row] for row in ai]
        self._track_w = var / self._tb
        self._track_left = 2 * k * self._ct_block
        self.bias_changes += 1
        self._ct_clear()
        return True

    def _mag(self, mx, my, mz, gx, gy, gz, dt):
        # _rot(_qmul(q_inc, q_gyr), m) written out (the same operations in the same order: the same bits)
        p0, p1, p2, p3 = self.q_inc
        q0, q1, q2, q3 = self.q_gyr
        r0 = p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3
        r1 = p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2
        r2 = p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1
        r3 = p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0
        ex = 2.0 * (mx * (0.5 - r2 * r2 - r3 * r3) + my * (r1 * r2 - r0 * r3) + mz * (r1 * r3 + r0 * r2))
        ey = 2.0 * (mx * (r1 * r2 + r0 * r3) + my * (0.5 - r1 * r1 - r3 * r3) + mz * (r2 * r3 - r0 * r1))
        ez = 2.0 * (mx * (r1 * r3 - r0 * r2) + my * (r2 * r3 + r0 * r1) + mz * (0.5 - r1 * r1 - r2 * r2))
        norm = _sqrt(ex * ex + ey * ey + ez * ez)
        hn = _sqrt(ex * ex + ey * ey)
        dip = _atan2(ez, hn)
        self.n_mag += 1
        if self.mag_ref is None:
            self.mag_ref = [norm, dip]
        ref = self.mag_ref
        c = self.cfg
        ok = abs(norm - ref[0]) < self._norm_th * ref[0] and abs(dip - ref[1]) < self._dip_th
        if ok:
            self.mag_disturbed = False
            self.mag_cand = None
            self.mag_cand_time = 0.0
            ref[0] += self._k_ref * (norm - ref[0])
            ref[1] += self._k_ref * (dip - ref[1])
        else:
            self.mag_disturbed = True
            cand = self.mag_cand
            if cand is not None and abs(norm - cand[0]) < c["mag_norm_th"] * cand[0] and abs(dip - cand[1]) < self._dip_th:
                cand[0] += self._k_ref * 5.0 * (norm - cand[0])
                cand[1] += self._k_ref * 5.0 * (dip - cand[1])
                if gx * gx + gy * gy + gz * gz > self._new_min_gyr2:
                    self.mag_cand_time += dt
                if self.mag_cand_time > c["mag_new_time_s"]:
                    self.mag_ref = [cand[0], cand[1]]
                    self.mag_cand = None
                    self.mag_cand_time = 0.0
                    self._m_new = True  # a new field: the bias rows' chain starts again
                    ok = True
            else:
                self.mag_cand = [norm, dip]
                self.mag_cand_time = 0.0
        if not ok or hn <= 0.0:
            return 0.0
        ms = self._msum
        ms[0] += ex
        ms[1] += ey
        ms[2] += ez
        self._mcount += 1
        # δ* puts the horizontal field on +y (north in ENU); _wrap written out
        err = (0.5 * _PI - _atan2(ey, ex) - self.delta + _PI) % _TWO_PI - _PI
        k = self._k_mag
        kn = 1.0 / self.n_mag
        if kn > k:
            k = kn
        step = k * err
        self.delta = (self.delta + step + _PI) % _TWO_PI - _PI
        return step


def _fit(rows, about=None):
    """Least-squares fit of a constant e to rows (y, h0, h1, h2): y = h·e + noise.

    Returns (e, A⁻¹, residual variance, F) with A = Σ hᵀh, the residual variance over n − 3 degrees of freedom
    (n rows) and F = (explained / 3) / residual variance, the regression's F statistic for e = ``about`` (default
    0); or None when the rows do not determine all three axes."""
    a00 = a01 = a02 = a11 = a12 = a22 = r0 = r1 = r2 = yy = 0.0
    n = 0
    for y, h0, h1, h2 in rows:
        a00 += h0 * h0
        a01 += h0 * h1
        a02 += h0 * h2
        a11 += h1 * h1
        a12 += h1 * h2
        a22 += h2 * h2
        r0 += h0 * y
        r1 += h1 * y
        r2 += h2 * y
        yy += y * y
        n += 1
    det = a00 * (a11 * a22 - a12 * a12) - a01 * (a01 * a22 - a12 * a02) + a02 * (a01 * a12 - a11 * a02)
    if n <= 3 or det <= 1e-9 * ((a00 + a11 + a22) / 3.0) ** 3:
        return None  # the turns in the window do not make all three axes observable
    ai = _inv3(((a00, a01, a02), (a01, a11, a12), (a02, a12, a22)))
    e = [ai[i][0] * r0 + ai[i][1] * r1 + ai[i][2] * r2 for i in range(3)]
    explained = e[0] * r0 + e[1] * r1 + e[2] * r2
    var = (yy - explained) / (n - 3)
    if var <= 0.0:
        return None
    if about is not None:  # (e − about)ᵀ A (e − about)
        d0, d1, d2 = e[0] - about[0], e[1] - about[1], e[2] - about[2]
        explained = (d0 * (a00 * d0 + a01 * d1 + a02 * d2) + d1 * (a01 * d0 + a11 * d1 + a12 * d2)
                     + d2 * (a02 * d0 + a12 * d1 + a22 * d2))
    return e, ai, var, explained / 3.0 / var


#: F quantiles (dfn, dfd, p) → value; the ones the defaults need (a window of 12 to 24 rows) are written here so that
#: the daemon does not import scipy (half a second) when it builds or runs its filter (tests/host/test_bias.py checks
#: them against scipy)
_F_QUANTILES = {(3, 9, 0.999): 13.901803191033137, (3, 10, 0.999): 12.552745388943725,
                (3, 11, 0.999): 11.561125849997026, (3, 12, 0.999): 10.80420437772044,
                (3, 13, 0.999): 10.208935588641129, (3, 14, 0.999): 9.729366314629939,
                (3, 15, 0.999): 9.335253584839293, (3, 16, 0.999): 9.005936855560376,
                (3, 17, 0.999): 8.72685203612592, (3, 18, 0.999): 8.48745452828306, (3, 19, 0.999): 8.2799321061764,
                (3, 20, 0.999): 8.098379786583402, (3, 21, 0.999): 7.938255045159838}


def _f_quantile(dfn: int, dfd: int, p: float) -> float:
    """The p-quantile of the F distribution with (dfn, dfd) degrees of freedom."""
    q = _F_QUANTILES.get((dfn, dfd, p))
    if q is None:
        from scipy.special import fdtri

        q = _F_QUANTILES[(dfn, dfd, p)] = float(fdtri(dfn, dfd, p))
    return q


def _inv3(a):
    """Inverse of a symmetric positive definite 3×3 matrix (adjugate / determinant)."""
    (a00, a01, a02), (_, a11, a12), (_, _, a22) = a
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    d = 1.0 / (a00 * c00 + a01 * c01 + a02 * c02)
    return [[c00 * d, c01 * d, c02 * d], [c01 * d, c11 * d, c12 * d], [c02 * d, c12 * d, c22 * d]]
