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

Gyro bias b: at **rest** (gyro and accelerometer steady for ``rest_min_s``) b follows the low-passed
gyro (``tau_bias_rest_s``); in **motion** b is nudged against the angular rate of the inclination and
heading corrections expressed in the sensor frame (``tau_bias_motion_s``), which is what a bias error
looks like; off by default, since on BROAD's fast translations the lagging low-pass makes those rates
correlate with the motion and the estimate wandered (mean total RMSE 2.20° off, 4.06° at 60 s).
b is clipped to ``bias_clip_dps``.

Settings were tuned once for all shipped BROAD trials together (host/docs/fusion.md), never per trial.
"""

from __future__ import annotations

import math

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
    tau_acc_s=4.5,
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
    tau_bias_rest_s=3.0,
    tau_bias_motion_s=0.0,  # 0 = off: on BROAD the motion bias estimate hurt more than it helped
    bias_clip_dps=2.0,
)


class SphereFilter:
    """Our best orientation filter (ENU). See the module docstring for the method; settings in ``DEFAULTS``."""

    earth_frame = EARTH_FRAME

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

    @property
    def settings(self) -> dict:
        return dict(self.cfg, earth_frame=EARTH_FRAME)

    @property
    def quat(self) -> np.ndarray:
        return np.array(self._quat())

    def _quat(self):
        h = 0.5 * self.delta
        qz = (math.cos(h), 0.0, 0.0, math.sin(h))
        return _norm4(_qmul(qz, _qmul(self.q_inc, self.q_gyr)))

    def _coeffs(self, dt):
        c = self.cfg
        k = lambda tau: 1.0 - math.exp(-dt / tau)  # noqa: E731
        self._dt = dt
        self._k_acc = k(0.5 * c["tau_acc_s"])  # per stage of the second-order low-pass
        self._k_mag = k(c["tau_mag_s"])
        self._k_ref = k(c["mag_ref_tau_s"])
        self._k_rest = k(c["rest_tau_s"])
        self._k_brest = k(c["tau_bias_rest_s"])
        self._k_bmot = dt / c["tau_bias_motion_s"] if c["tau_bias_motion_s"] > 0 else 0.0
        self._bias_clip = math.radians(c["bias_clip_dps"])
        self._rest_gyr2 = math.radians(c["rest_th_gyr_dps"]) ** 2
        self._rest_acc2 = c["rest_th_acc_m_s2"] ** 2
        self._new_min_gyr2 = math.radians(c["mag_new_min_gyr_dps"]) ** 2
        self._dip_th = math.radians(c["mag_dip_th_deg"])

    def update(self, gyr_rad_s, acc_m_s2, mag_uT, dt_s: float, *, acc_valid: bool = True, mag_valid: bool = True):
        gx, gy, gz = gyr_rad_s
        ax, ay, az = acc_m_s2
        m = None if (mag_uT is None or not mag_valid) else mag_uT
        self._step(float(gx), float(gy), float(gz), float(ax), float(ay), float(az), m, float(dt_s), acc_valid)
        return self._quat()

    def update_batch(self, gyr, acc, mag, dt_s: float, *, acc_valid=None, mag_valid=None) -> np.ndarray:
        """Run the per-sample step over (N, 3) arrays; returns (N, 4). ``mag`` may be None."""
        gyr, acc, magl, av, mv = batch_inputs(gyr, acc, mag, acc_valid, mag_valid)
        n = len(gyr)
        out = np.empty((n, 4))
        dt = float(dt_s)
        step = self._step
        quat = self._quat
        for i in range(n):
            g = gyr[i]
            a = acc[i]
            step(g[0], g[1], g[2], a[0], a[1], a[2], magl[i] if mv[i] else None, dt, av[i])
            out[i] = quat()
        return out

    # -- the filter ---------------------------------------------------------------------------------
    def _step(self, gx, gy, gz, ax, ay, az, m, dt, acc_valid):
        if dt != self._dt:
            self._coeffs(dt)
        self._rest(gx, gy, gz, ax, ay, az, dt)
        b = self.bias
        wx, wy, wz = gx - b[0], gy - b[1], gz - b[2]

        # 1. strapdown: q_gyr ← q_gyr ⊗ exp(½ ω dt)
        wn = math.sqrt(wx * wx + wy * wy + wz * wz)
        if wn > 1e-12:
            ang = 0.5 * wn * dt
            s = math.sin(ang) / wn
            qg = _qmul(self.q_gyr, (math.cos(ang), wx * s, wy * s, wz * s))
            self.q_gyr = _norm4(qg)

        cx = cy = cz = 0.0  # correction rates (earth frame E′), rad per sample
        # 2. inclination from the accelerometer low-passed in frame I
        if acc_valid and (ax or ay or az):
            ix, iy, iz = _rot(self.q_gyr, ax, ay, az)
            self.n_acc += 1
            k = max(self._k_acc, 1.0 / self.n_acc)
            # second-order low-pass: two first-order stages of τ/2 each (critically damped)
            l1 = self.acc_lp1
            l1[0] += k * (ix - l1[0])
            l1[1] += k * (iy - l1[1])
            l1[2] += k * (iz - l1[2])
            lp = self.acc_lp
            lp[0] += k * (l1[0] - lp[0])
            lp[1] += k * (l1[1] - lp[1])
            lp[2] += k * (l1[2] - lp[2])
            vx, vy, vz = _rot(self.q_inc, lp[0], lp[1], lp[2])
            vn = math.sqrt(vx * vx + vy * vy + vz * vz)
            if vn > 0.0:
                vx, vy, vz = vx / vn, vy / vn, vz / vn
                # smallest rotation taking v to +z: axis v × z = (vy, −vx, 0)
                w = 1.0 + vz
                if w > 1e-9:
                    rn = 1.0 / math.sqrt(w * w + vx * vx + vy * vy)
                    r = (w * rn, vy * rn, -vx * rn, 0.0)
                else:
                    r = (0.0, 1.0, 0.0, 0.0)
                self.q_inc = _norm4(_qmul(r, self.q_inc))
                cx, cy = 2.0 * r[1], 2.0 * r[2]

        # 3. heading from the magnetometer, with disturbance detection
        if m is not None:
            mx, my, mz = m
            mx, my, mz = float(mx), float(my), float(mz)
            if mx or my or mz:
                cz = self._mag(mx, my, mz, gx, gy, gz, dt)

        # 4. bias in motion: the corrections' rate in the sensor frame is minus the bias error
        if self._k_bmot and not self.at_rest and (cx or cy or cz):
            q6 = _qmul(self.q_inc, self.q_gyr)
            # earth→sensor: rotate by q6*
            qc = (q6[0], -q6[1], -q6[2], -q6[3])
            # heading correction is about earth z, applied after R_z(δ); z is invariant under it
            sx, sy, sz = _rot(qc, cx, cy, cz)
            k = self._k_bmot / dt
            clip = self._bias_clip
            for i, s_ in enumerate((sx, sy, sz)):
                v = b[i] - k * s_
                b[i] = clip if v > clip else (-clip if v < -clip else v)

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
        if self.at_rest:
            b = self.bias
            kb = self._k_brest
            b[0] += kb * (rg[0] - b[0])
            b[1] += kb * (rg[1] - b[1])
            b[2] += kb * (rg[2] - b[2])
