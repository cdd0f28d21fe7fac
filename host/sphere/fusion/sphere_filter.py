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
sensor turns. b is clipped to ``bias_clip_dps``, each diagonal of P to its initial value.

That prior (σ_motion) makes the filter slow in motion on purpose: real hand motion leaves bias-like errors in
the measurement (lever arm, scale factors) that a fast filter would follow. A bias that really changes (a step)
is caught by a **change test** on the same measurements (``_change_test``): an F-test of a constant bias error
fitted over K = ``bias_change_blocks`` one-second blocks, significant at ``bias_change_alpha`` in two consecutive
windows that agree. Then b restarts from the latest window's least-squares fit of the bias itself, with the
covariance that fit has (not P₀, which threw the window's data away), and for 2K blocks the filter uses the
measurement noise that fit showed (no process noise), so it settles in seconds. Its threshold is a
quantile of the F distribution, not a tuned value.

The free settings (``tau_acc_s``, ``bias_sigma_motion_dps``, ``bias_forget_s``) are the ones ``sphere eval --cv``
chose, leave one trial out (host/docs/fusion.md); the rest are VQF's published defaults where VQF has one.
"""

from __future__ import annotations

import math
from math import cos as _cos, sin as _sin, sqrt as _sqrt

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


def _wrap(a):
    return (a + math.pi) % (2.0 * math.pi) - math.pi


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
        self._blp3_prev = [0.0] * 10
        # the change test (see _change_test): sums over the current block, the finished blocks' means
        self._ct_sum = [0.0] * 8
        self._ct_n = 0
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
        self._ct_block = max(1, int(round(c["bias_change_block_s"] / tb)))
        self._rest_gyr2 = math.radians(c["rest_th_gyr_dps"]) ** 2
        self._rest_acc2 = c["rest_th_acc_m_s2"] ** 2
        self._new_min_gyr2 = math.radians(c["mag_new_min_gyr_dps"]) ** 2
        self._dip_th = math.radians(c["mag_dip_th_deg"])

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
        self._rest(gx, gy, gz, ax, ay, az, dt)
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
        l3, prev = self._blp3, self._blp3_prev
        prev[:] = l3
        l3[:8] = [a + k3 * (c - a) for a, c in zip(l3, lp)]
        l3[8] += k3 * (it[8] - l3[8])
        l3[9] += k3 * (it[9] - l3[9])
        g = 1.0 / tb
        d = [(a - c) * g for a, c in zip(l3, prev)]
        P = self.bias_P
        v, p0 = self._b_v, self._b_p0
        if self._track_left:
            v = 0.0  # after a detected change the bias is taken as constant while the data pin it down
        for i in range(3):
            P[i][i] = min(P[i][i] + v, p0)
        if self.at_rest:
            if self._ct_n or self._ct_blocks:
                self._ct_clear()
            self._track_left = 0
            # measurement: the low-passed gyro at rest, H = I
            w = self._b_wrest
            S = [[P[i][j] + (w if i == j else 0.0) for j in range(3)] for i in range(3)]
            Si = _inv3(S)
            S0, S1, S2 = Si
            K = [[sum((Pi[0] * S0[j], Pi[1] * S1[j], Pi[2] * S2[j])) for j in range(3)] for Pi in P]
            rg = self.rest_gyr
            y = (rg[0] - b[0], rg[1] - b[1], rg[2] - b[2])
            H = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
        elif self._b_wmot:
            # measurement: z = ΔF[Ψ] − ΔC = ΔF[Φ]·b_true + noise (rates over the step), H = ΔF[Φ]
            H = ((d[0], d[1], d[2]), (d[3], d[4], d[5]))
            y = (d[6] - d[8] - (d[0] * b[0] + d[1] * b[1] + d[2] * b[2]),
                 d[7] - d[9] - (d[3] * b[0] + d[4] * b[1] + d[5] * b[2]))
            PH = [[P[i][0] * h[0] + P[i][1] * h[1] + P[i][2] * h[2] for h in H] for i in range(3)]  # P Hᵀ, 3×2
            w = self._b_wmot
            if self._track_left:
                self._track_left -= 1
                w = self._track_w
            if self.n_acc * self._k_acc < 1.0:
                # the accelerometer low-pass still averages (gain 1/n > k): c is noisier by about 1/(n·k)
                w /= max(self.n_acc * self._k_acc, 1e-3) ** 2
            s00 = H[0][0] * PH[0][0] + H[0][1] * PH[1][0] + H[0][2] * PH[2][0] + w
            s01 = H[0][0] * PH[0][1] + H[0][1] * PH[1][1] + H[0][2] * PH[2][1]
            s11 = H[1][0] * PH[0][1] + H[1][1] * PH[1][1] + H[1][2] * PH[2][1] + w
            det = s00 * s11 - s01 * s01
            i00, i01, i11 = s11 / det, -s01 / det, s00 / det
            K = [[PH[i][0] * i00 + PH[i][1] * i01, PH[i][0] * i01 + PH[i][1] * i11] for i in range(3)]
            if self._ct_f is not None and self.cfg["bias_change_test"] and self._change_test(H, y):
                return
        else:
            return
        # the sums below are sum() over tuples written out (no generators; the same additions in the same order)
        clip = self._bias_clip
        if len(y) == 2:
            y0, y1 = y
            H0, H1 = H
            Ky = [sum((Ki[0] * y0, Ki[1] * y1)) for Ki in K]
            KH = [[sum((Ki[0] * H0[0], Ki[1] * H1[0])), sum((Ki[0] * H0[1], Ki[1] * H1[1])),
                   sum((Ki[0] * H0[2], Ki[1] * H1[2]))] for Ki in K]
        else:
            y0, y1, y2 = y
            H0, H1, H2 = H
            Ky = [sum((Ki[0] * y0, Ki[1] * y1, Ki[2] * y2)) for Ki in K]
            KH = [[sum((Ki[0] * H0[0], Ki[1] * H1[0], Ki[2] * H2[0])),
                   sum((Ki[0] * H0[1], Ki[1] * H1[1], Ki[2] * H2[1])),
                   sum((Ki[0] * H0[2], Ki[1] * H1[2], Ki[2] * H2[2]))] for Ki in K]
        for i in range(3):
            v_ = b[i] + Ky[i]
            b[i] = clip if v_ > clip else (-clip if v_ < -clip else v_)
        # P ← (I − K H) P, kept symmetric
        P0, P1, P2 = P
        (n00, n01, n02), (n10, n11, n12), (n20, n21, n22) = [
            [Pi[0] - sum((KHi[0] * P0[0], KHi[1] * P1[0], KHi[2] * P2[0])),
             Pi[1] - sum((KHi[0] * P0[1], KHi[1] * P1[1], KHi[2] * P2[1])),
             Pi[2] - sum((KHi[0] * P0[2], KHi[1] * P1[2], KHi[2] * P2[2]))] for Pi, KHi in zip(P, KH)]
        self.bias_P = [[0.5 * (n00 + n00), 0.5 * (n01 + n10), 0.5 * (n02 + n20)],
                       [0.5 * (n10 + n01), 0.5 * (n11 + n11), 0.5 * (n12 + n21)],
                       [0.5 * (n20 + n02), 0.5 * (n21 + n12), 0.5 * (n22 + n22)]]

    def _ct_clear(self):
        self._ct_sum[:] = [0.0] * 8
        self._ct_n = 0
        self._ct_blocks.clear()

    def _change_test(self, H, y) -> bool:
        """Has the bias changed? A test on the motion measurements' innovations y = H·e + noise (e = b_true − b).

        The innovations of the bias steps are averaged over blocks of ``bias_change_block_s`` (1 s: the hand's
        oscillations and the third low-pass stage make neighbouring steps strongly correlated, the block means
        much less so), H alike. Over a window of K = ``bias_change_blocks`` blocks (2K rows) a constant error e
        is fitted by least squares; with the noise variance estimated from the fit's own residuals, the statistic
        F = (explained / 3) / (residual / (2K − 3)) is F-distributed with (3, 2K − 3) degrees of freedom when
        e = 0 (the F-test of a linear regression): the threshold is its 1 − ``bias_change_alpha`` quantile, a
        statistic of the noise, not a tuned value. A bias change must show in two consecutive windows (the last
        2K blocks), each significant, and the two estimates of the bias (b + e, each at its window's end) must
        agree (the same F quantile on their difference): real hand motion produces bias-like errors too (on BROAD's
        fast rotations, flipping every few seconds), a changed bias stays. What follows a change is described
        below; the blocks start afresh. Returns True when it did so (the Kalman update of this step is skipped)."""
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
        self._ct_n += 1
        if self._ct_n < self._ct_block:
            return False
        blocks = self._ct_blocks
        g = 1.0 / self._ct_n
        b = self.bias
        blocks.append([v * g for v in s] + b)
        s[:] = [0.0] * 8
        self._ct_n = 0
        k = self._ct_k
        if len(blocks) > 2 * k:
            del blocks[0]
        if len(blocks) < 2 * k:
            return False
        cur = _fit(blocks[k:])
        if cur is None or cur[3] < self._ct_f:
            return False
        prev = _fit(blocks[:k])
        if prev is None or prev[3] < self._ct_f:
            return False
        # the two windows' estimates of the bias itself (b at the window's end + e), each with covariance var·A⁻¹
        bp = [blocks[k - 1][8 + i] + prev[0][i] for i in range(3)]
        bc = [b[i] + cur[0][i] for i in range(3)]
        vp = [[prev[2] * a for a in row] for row in prev[1]]
        vc = [[cur[2] * a for a in row] for row in cur[1]]
        d = [bc[i] - bp[i] for i in range(3)]
        si = _inv3([[vp[i][j] + vc[i][j] for j in range(3)] for i in range(3)])
        if sum(d[i] * si[i][j] * d[j] for i in range(3) for j in range(3)) / 3.0 > self._ct_f:
            return False  # both significant, but not the same bias: motion, not a change
        # the change: b starts again from the latest window's own fit of the bias itself (not of a constant error
        # e = b_true − b: b moved during the window, so the measurements' bias-like part is z = y + H·b_block, fitted
        # as one constant; blocks keep b at their end), with the covariance that fit has (var·A⁻¹, the information of
        # the window's K s of data, where P₀ threw it away), and for the next 2K blocks the Kalman filter takes the
        # measurement noise that fit showed (its residual variance of 1 s means, per step as _b_wmot is) and no
        # process noise: the new, constant bias is pinned down at the rate the data allow, not at the slow rate the
        # prior σ_motion sets
        win = _fit([[y0 + h0 * c0 + h1 * c1 + h2 * c2, y1 + h3 * c0 + h4 * c1 + h5 * c2, h0, h1, h2, h3, h4, h5]
                    for y0, y1, h0, h1, h2, h3, h4, h5, c0, c1, c2 in blocks[k:]])
        if win is None:  # cannot happen with cur's rows unless the fit is exact; then b + e with P₀ as a fallback
            win = (bc, [[self._b_p0 / cur[2] if i == j else 0.0 for j in range(3)] for i in range(3)], cur[2], 0.0)
        bw, ai, var, _ = win
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
        q6 = _qmul(self.q_inc, self.q_gyr)
        ex, ey, ez = _rot(q6, mx, my, mz)
        norm = math.sqrt(ex * ex + ey * ey + ez * ez)
        hn = math.sqrt(ex * ex + ey * ey)
        dip = math.atan2(ez, hn)
        self.n_mag += 1
        if self.mag_ref is None:
            self.mag_ref = [norm, dip]
        ref = self.mag_ref
        c = self.cfg
        ok = abs(norm - ref[0]) < c["mag_norm_th"] * ref[0] and abs(dip - ref[1]) < self._dip_th
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
                    ok = True
            else:
                self.mag_cand = [norm, dip]
                self.mag_cand_time = 0.0
        if not ok or hn <= 0.0:
            return 0.0
        # δ* puts the horizontal field on +y (north in ENU)
        err = _wrap(0.5 * math.pi - math.atan2(ey, ex) - self.delta)
        k = max(self._k_mag, 1.0 / self.n_mag)
        step = k * err
        self.delta = _wrap(self.delta + step)
        return step

    def _rest(self, gx, gy, gz, ax, ay, az, dt):
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
        self.at_rest = self.rest_time >= self.cfg["rest_min_s"]


def _fit(blocks):
    """Least-squares fit of a constant e to block means (y0, y1, h0..h5, ...): (y0, y1) = [h0 h1 h2; h3 h4 h5]·e.

    Returns (e, A⁻¹, residual variance, F) with A = Σ hᵀh, the residual variance over 2n − 3 degrees of freedom
    and F = (explained / 3) / residual variance, the regression's F statistic for e = 0; or None when the rows
    do not determine all three axes."""
    a00 = a01 = a02 = a11 = a12 = a22 = r0 = r1 = r2 = yy = 0.0
    for y0, y1, h0, h1, h2, h3, h4, h5, *_ in blocks:
        a00 += h0 * h0 + h3 * h3
        a01 += h0 * h1 + h3 * h4
        a02 += h0 * h2 + h3 * h5
        a11 += h1 * h1 + h4 * h4
        a12 += h1 * h2 + h4 * h5
        a22 += h2 * h2 + h5 * h5
        r0 += h0 * y0 + h3 * y1
        r1 += h1 * y0 + h4 * y1
        r2 += h2 * y0 + h5 * y1
        yy += y0 * y0 + y1 * y1
    det = a00 * (a11 * a22 - a12 * a12) - a01 * (a01 * a22 - a12 * a02) + a02 * (a01 * a12 - a11 * a02)
    if det <= 1e-9 * ((a00 + a11 + a22) / 3.0) ** 3:
        return None  # the turns in the window do not make all three axes observable
    ai = _inv3(((a00, a01, a02), (a01, a11, a12), (a02, a12, a22)))
    e = [ai[i][0] * r0 + ai[i][1] * r1 + ai[i][2] * r2 for i in range(3)]
    explained = e[0] * r0 + e[1] * r1 + e[2] * r2
    var = (yy - explained) / (2 * len(blocks) - 3)
    if var <= 0.0:
        return None
    return e, ai, var, explained / 3.0 / var


#: F quantiles (dfn, dfd, p) → value; the one the defaults need is written here so that the daemon does not import
#: scipy (half a second) when it builds its filter (tests/host/test_bias.py checks it against scipy)
_F_QUANTILES = {(3, 9, 0.999): 13.901803191033137}


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
