"""SphereFilter: our orientation filter for the sphere (earth frame **ENU**, quat sensor-to-ENU).

Plain Python floats, no numpy in the hot path, so one update costs a few microseconds (``sphere bench fusion``).
The estimate is split into three parts, q = R_z(δ) ⊗ q_inc ⊗ q_gyr (the structure VQF made popular; Laidig &
Seel 2023), each corrected by a different sensor:

1. **Strapdown** q_gyr: bias-corrected gyro ω − b integrated exactly (axis-angle step) into a frame I
   that drifts only slowly (bias residue).
2. **Inclination** q_inc (I → E′): the accelerometer is rotated into I and low-pass filtered there
   (second order: two first-order stages of ``tau_acc_s``/2, so a 1.5 Hz hand motion is attenuated
   ~400×, not ~40× as by one stage). Linear accelerations, taps and vibration have zero mean in a frame that
   does not rotate with the hand, so they average out while gravity stays; q_inc is then set so the
   filtered vector points up. ``acc_valid=False`` (a tap in progress) skips the sample.
3. **Heading** δ about the vertical: from the magnetometer rotated into E′, the azimuth of its horizontal
   part is pulled to north (+y) with time constant ``tau_mag_s``, but only while the field looks like the
   earth's (``mag_reject``): norm within ``mag_norm_th`` (relative) and dip within ``mag_dip_th_deg`` of a
   reference learned while undisturbed. While disturbed, heading is held on the gyro. A field that passes the
   test is trusted by how close it is to the reference (``mag_weight``): the gain is multiplied by
   (1 − |Δnorm|/(``mag_norm_th``·norm)) · (1 − |Δdip|/``mag_dip_th_deg``), 1 for the earth's field as learnt, 0 where
   the test would reject it, so a field distorted by less than the test catches (a magnet some way off, the
   gradients of a room) pulls the heading less than the earth's own, and the earth's own can be followed faster.

Gyro bias b: a small Kalman filter (state b, covariance P, 3×3) run every ``bias_step_s``. Its prediction adds
process noise (``bias_sigma_init_dps``² per ``bias_forget_s``, each diagonal capped at its start value), its
measurement (``bias_rest``) is the low-passed gyro while the sensor is at **rest** (gyro and accelerometer steady
for ``rest_min_s``, as VQF detects it; noise ``bias_sigma_rest_dps``). b is clipped to ``bias_clip_dps``.

That is all: the parts that were here besides (a bias measurement in motion from the inclination corrections and
from the field's turning, a χ² test on the latter, a change test for bias steps, the acceptance of a new field)
did not earn their place when the structure was chosen by nested leave-one-trial-out on the shipped BROAD trials
(host/docs/fusion.md, "Which filter wins where nobody tuned it"). The three parts are switches (``PARTS``), so
``sphere eval --cv`` keeps checking that each earns its place; the settings are the point it chose.
"""

from __future__ import annotations

import itertools
import math
from math import atan2 as _atan2, cos as _cos, sin as _sin, sqrt as _sqrt

import numpy as np

from sphere.fusion.common import batch_inputs
from sphere.settings import Param

EARTH_FRAME = "ENU"


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
    tau_mag_s=6.0,
    mag_norm_th=0.05,
    mag_dip_th_deg=5.0,
    mag_ref_tau_s=20.0,
    rest_min_s=1.5,
    rest_tau_s=0.5,
    rest_th_gyr_dps=2.0,
    rest_th_acc_m_s2=0.5,
    bias_step_s=0.05,
    bias_sigma_init_dps=0.5,
    bias_forget_s=100.0,
    bias_sigma_rest_dps=0.03,
    bias_clip_dps=2.0,
    # the parts, each switchable so that `sphere eval --cv` chooses the structure as it chooses parameters
    bias_rest=True,  # the rest measurement of the bias (the low-passed gyro while still)
    mag_reject=True,  # the field's disturbance test (norm and dip against the reference); off: every reading is used
    mag_weight=True,  # the heading's gain falls as the field's norm and dip move from the reference (0 at the test)
)

#: the switchable parts (each a boolean of DEFAULTS)
PARTS = ("bias_rest", "mag_reject", "mag_weight")
#: the structure variants `sphere eval --cv` chooses among (nested), simplest first
STRUCTURES = tuple(sorted((dict(zip(PARTS, v)) for v in itertools.product((False, True), repeat=len(PARTS))),
                          key=lambda p: sum(p.values())))


class SphereFilter:
    """Our orientation filter (ENU). See the module docstring for the method; settings in ``DEFAULTS``, of which
    ``PARAMS`` are the free ones and the part switches (``sphere eval --cv`` chooses them from ``GRID`` and
    ``STRUCTURES``)."""

    earth_frame = EARTH_FRAME
    NAME = "sphere"
    PARAMS = {
        "tau_acc_s": Param(DEFAULTS["tau_acc_s"], "s", 0.1, 60.0, "time constant of the accelerometer's low-pass "
                                                                  "in the gyro frame (two stages of half of it)"),
        "tau_mag_s": Param(DEFAULTS["tau_mag_s"], "s", 0.5, 300.0, "time constant with which the heading follows "
                                                                   "an undisturbed field"),
        "bias_rest": Param(DEFAULTS["bias_rest"], doc="the rest measurement of the bias (the low-passed gyro while "
                                                      "still)"),
        "mag_reject": Param(DEFAULTS["mag_reject"], doc="the field's disturbance test (norm and dip against the "
                                                        "reference); off: every reading is used"),
        "mag_weight": Param(DEFAULTS["mag_weight"], doc="the heading's gain falls linearly as the field's norm and dip "
                                                        "move from the reference, to 0 where the test would reject "
                                                        "it; off: the full gain for every field accepted"),
    }
    GRID = {"tau_acc_s": (3.0, 4.5), "tau_mag_s": (6.0, 9.0, 15.0)}
    #: the structure variants `sphere eval --cv` chooses among (nested), simplest first
    STRUCTURES = STRUCTURES
    LIVE = True  # the daemon can run it (per-sample update with acc_valid / mag_valid)

    @classmethod
    def from_settings(cls, s, dt_s=None, q0=None, gyro_bias_rad_s=None):
        """It initialises itself from its first samples and estimates its own bias (no q0, no start-up bias)."""
        return cls(**s.as_dict())

    #: ``update_batch(..., diagnostics=True)`` returns the per-sample rest flag, bias and disturbance flag
    diagnostics = ("rest", "bias_rad_s", "mag_disturbed")

    def __init__(self, **settings):
        unknown = set(settings) - set(DEFAULTS)
        if unknown:
            raise TypeError(f"unknown SphereFilter settings: {', '.join(sorted(unknown))}")
        self.cfg = dict(DEFAULTS, **settings)
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
        self.mag_disturbed = False
        self.rest_gyr = [0.0, 0.0, 0.0]
        self.rest_acc = [0.0, 0.0, 0.0]
        self.rest_time = 0.0
        self.at_rest = False
        self._rest_init = False
        self._dt = None
        self._nb = 0
        #: a bias step is due and was deferred (``update(..., defer_bias=True)``); ``run_deferred`` runs it
        self.bias_pending = False

    @property
    def settings(self) -> dict:
        return dict(self.cfg, earth_frame=EARTH_FRAME)

    @property
    def quat(self) -> np.ndarray:
        return np.array(self._quat())

    def _quat(self):
        # _norm4(quaternion.mul(qz, quaternion.mul(q_inc, q_gyr))), qz = (cos h, 0, 0, sin h), written out
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
        d2 = math.radians(1.0) ** 2
        self._b_p0 = c["bias_sigma_init_dps"] ** 2 * d2
        self._b_v = self._b_p0 * tb / c["bias_forget_s"]  # process noise per bias step
        self._b_wrest = c["bias_sigma_rest_dps"] ** 2 * d2
        self._bias_clip = math.radians(c["bias_clip_dps"])
        self._rest_gyr2 = math.radians(c["rest_th_gyr_dps"]) ** 2
        self._rest_acc2 = c["rest_th_acc_m_s2"] ** 2
        self._dip_th = math.radians(c["mag_dip_th_deg"])
        self._norm_th = c["mag_norm_th"]
        self._rest_on = bool(c["bias_rest"])
        self._reject_on = bool(c["mag_reject"])
        self._rest_min = c["rest_min_s"]
        self._weight_on = bool(c["mag_weight"])

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
        # the quaternion products (sphere.quaternion.mul), rotations and normalisations of _rot and _norm4 are
        # written out here (the same operations in the same order: the same bits, tests/host/test_fusion.py checks
        # it), as this runs at every sample: as quaternion.mul calls they make update 5 % slower (7.36 against
        # 7.01 µs per sample, CPU time, median of 16 alternating runs over bias_scenarios "motion", same bits)
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

        # 3. heading from the magnetometer, with disturbance detection
        if m is not None:
            mx, my, mz = m
            mx, my, mz = float(mx), float(my), float(mz)
            if mx or my or mz:
                self._mag(mx, my, mz)

        # 4. gyro bias, every bias_step_s
        self._nb += 1
        if self._nb >= self._nb_step:
            if defer_bias:
                self.bias_pending = True
            else:
                self._bias_step()

    def _bias_step(self):
        """One step of the bias Kalman filter: the prediction, and at rest the measurement (the low-passed gyro,
        H = I), in information form: P⁺ = (P⁻¹ + Σ hᵀh / w)⁻¹, b⁺ = b + P⁺ Σ hᵀ y / w."""
        self.bias_pending = False
        self._nb = 0
        b = self.bias
        P = self.bias_P
        v, p0 = self._b_v, self._b_p0
        for i in range(3):
            P[i][i] = min(P[i][i] + v, p0)
        if not (self.at_rest and self._rest_on):
            return
        b0, b1, b2 = b
        iw = 1.0 / self._b_wrest
        rg = self.rest_gyr
        rows = ((1.0, 0.0, 0.0, rg[0] - b0, iw), (0.0, 1.0, 0.0, rg[1] - b1, iw), (0.0, 0.0, 1.0, rg[2] - b2, iw))
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

    def _mag(self, mx, my, mz):
        # _rot(quaternion.mul(q_inc, q_gyr), m) written out (the same operations in the same order: the same bits)
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
        if self._reject_on and not (abs(norm - ref[0]) < self._norm_th * ref[0] and abs(dip - ref[1]) < self._dip_th):
            self.mag_disturbed = True
            return
        self.mag_disturbed = False
        ref[0] += self._k_ref * (norm - ref[0])
        ref[1] += self._k_ref * (dip - ref[1])
        if hn <= 0.0:
            return
        # δ* puts the horizontal field on +y (north in ENU); _wrap written out
        err = (0.5 * _PI - _atan2(ey, ex) - self.delta + _PI) % _TWO_PI - _PI
        k = self._k_mag
        if self._weight_on:
            # a field that differs from the earth's by part of what the test allows is trusted by that much less:
            # the gain falls linearly with each relative deviation and is 0 where the test would reject it
            wn_ = 1.0 - abs(norm - ref[0]) / (self._norm_th * ref[0])
            wd_ = 1.0 - abs(dip - ref[1]) / self._dip_th
            w_ = wn_ * wd_ if wn_ > 0.0 and wd_ > 0.0 else 0.0
            k *= w_
        kn = 1.0 / self.n_mag
        if kn > k:
            k = kn
        self.delta = (self.delta + k * err + _PI) % _TWO_PI - _PI


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
