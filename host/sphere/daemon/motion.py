"""What the sphere is doing now, from its packets: bias-corrected angular rate, the vertical, orientation.

RAW_SAMPLE gyro values are uncalibrated chip units (14.375 LSB per °/s). :class:`GyroBias` re-estimates
the bias whenever the sphere lies still, as gyro-mouse software does ("continuous calibration").
Orientation comes from the host's fusion filter run on the raw samples (``sphere.fusion``), or from
the firmware's ORIENTATION packets (Q14, sensor-to-NWU).
"""

from __future__ import annotations

import math

from sphere import chips
from sphere import quaternion
from sphere.protocol.packets import RAW_ACCEL_OK, RAW_GYRO_OK, RAW_GYRO_STALE, RAW_MAG_OK, RAW_TAP_ACTIVE

G_M_S2 = chips.STANDARD_GRAVITY_M_S2
DEG = math.pi / 180.0
_GYRO_DPS_PER_LSB = 1.0 / chips.ITG3200_LSB_PER_DPS
_ACCEL_G_PER_LSB = 1.0 / chips.ADXL345_LSB_PER_G
_MAG_UT_PER_LSB = 1.0 / chips.HMC5883L_LSB_PER_UT
MAG_STILL_UT = 0.2  # µT per still window: the compass trend test's floor (HMC5883L noise ≈ 0.2 µT, 1 LSB 0.09 µT)


class _Trend:
    """Running sums for the least-squares slope of a 3-vector against time over one window."""

    __slots__ = ("n", "fresh", "st", "stt", "sx", "stx", "sxx", "last", "t0")

    def __init__(self):
        self.t0 = None
        self.n = self.fresh = 0
        self.st = self.stt = 0.0
        self.sx = [0.0] * 3
        self.stx = [0.0] * 3
        self.sxx = [0.0] * 3
        self.last = None

    def add(self, t: float, v) -> None:
        t0 = self.t0
        if t0 is None:
            t0 = self.t0 = t
        t -= t0
        self.n += 1
        if v != self.last:
            self.fresh += 1
            self.last = v
        self.st += t
        self.stt += t * t
        x0, x1, x2 = v  # written out: this runs twice per sample
        sx, stx, sxx = self.sx, self.stx, self.sxx
        sx[0] += x0
        stx[0] += t * x0
        sxx[0] += x0 * x0
        sx[1] += x1
        stx[1] += t * x1
        sxx[1] += x1 * x1
        sx[2] += x2
        stx[2] += t * x2
        sxx[2] += x2 * x2

    def moved(self, floor: float, k_sigma: float = 4.0) -> bool:
        """Whether the vector changed over the window by more than ``k_sigma`` standard errors of the fitted
        slope (from the window's own scatter about the line; repeated readings count once) and ``floor``."""
        n = self.n
        if n < 4:
            return False
        stt = self.stt - self.st * self.st / n
        if stt <= 0:
            return False
        span = math.sqrt(12.0 * stt / n)  # the window's length in time
        n_eff = max(3, min(self.fresh, n))
        for i in range(3):
            stx = self.stx[i] - self.st * self.sx[i] / n
            sxx = self.sxx[i] - self.sx[i] * self.sx[i] / n
            b = stx / stt
            var = max(0.0, (sxx - b * stx) / (n - 2))
            se = math.sqrt(var / stt * n / n_eff)
            if abs(b) * span > max(k_sigma * se * span, floor):
                return True
        return False


class GyroBias:
    """Gyro bias in °/s, learnt from windows of ``still_time_s`` in which the sphere lies still.

    A window counts as still only when all of these hold — a slow steady turn fails at least one:

    - the gyro stays within ±``still_dps`` of its range's middle on every axis (hand tremor fails this);
    - the accelerometer's magnitude stays near 1 g, and its direction shows no trend: the fitted change over
      the window is below 4 standard errors of the slope (estimated from the window's own scatter, so the
      threshold scales with the window and its noise) and below one LSB (3.9 mg ≈ a 0.2 °/s turn about a
      horizontal axis). A turn about any axis but the vertical tips gravity in the sensor frame;
    - the magnetometer, when it answers, confirms the same way (a turn about the vertical swings the field's
      horizontal part: 3 °/s turns 20 µT by 1 µT a second, ~12 standard errors of a 1-s window of HMC5883L
      noise); ``MAG_STILL_UT`` is its floor per window.

    Then the window's mean must be plausible for the chip (``|bias| ≤ MAX_BIAS_DPS``) and, once a bias is
    known, close to it: within ``base_dps`` plus ``drift_dps_per_s`` for every second since the last update
    (a bias moves slowly, with temperature). A window that is not is held back; a second still window in a
    row that agrees with it replaces the bias if the two together pass the trend tests again (twice the
    time: 2.8 times as sensitive, so a turn too slow for one window's test is caught) — recovery from a
    wrong estimate, e.g. one learnt during a steady turn at start-up while the compass was not answering.
    A window the compass confirmed replaces one it did not confirm at once.
    """

    MAX_BIAS_DPS = 40.0  # ITG-3200 datasheet (PS-ITG-3200A-00-01.4) §3.1 Sensor Specifications: initial ZRO tolerance ±40 °/s
    ACCEL_FLOOR_G = 1.0 / 256  # one ADXL345 LSB at full resolution
    AVERAGE_WINDOWS = 8

    def __init__(self, still_dps: float = 3.0, still_time_s: float = 1.0, enabled: bool = True,
                 base_dps: float = 0.15, drift_dps_per_s: float = 0.02):
        self.still_dps = still_dps
        self.still_time_s = still_time_s
        self.enabled = enabled
        self.base_dps = base_dps
        self.drift_dps_per_s = drift_dps_per_s
        self.bias = [0.0, 0.0, 0.0]
        self.updates = 0
        self.confirmed = False  # the current bias came from a window the compass confirmed
        self.rejected = 0  # still windows held back as too far from the current bias
        self._clock = 0.0
        self._last_update_s = 0.0
        self._pending = None  # (mean, confirmed) of the last window held back
        self._long = None  # its accelerometer and compass trends, carried on over the next window
        self._windows = 0
        self._queued = None  # a sample left for run_deferred (add(..., defer=True))
        self._start()

    def _start(self):
        self._n = 0
        self._t = 0.0
        self._sum = [0.0, 0.0, 0.0]
        self._lo = [math.inf] * 3
        self._hi = [-math.inf] * 3
        self._accel_ok = True
        self._acc = _Trend()
        self._mag = _Trend()

    def add(self, gyro_dps, accel_g_norm: float, dt_s: float, mag_uT=None, accel_g=None, defer: bool = False) -> None:
        """One sample. ``defer=True`` leaves it for :meth:`run_deferred` (so the caller can act on the sample
        first) when it cannot end a window — only a window's end changes the bias — and takes it at once when it
        may; the next add() takes a sample left behind first. The result is the same bit for bit."""
        if not self.enabled:
            return
        if self._queued is not None:
            self.run_deferred()
        if defer and self._t + dt_s < self.still_time_s:  # the same sum as below: this sample ends no window
            self._queued = (gyro_dps, accel_g_norm, dt_s, mag_uT, accel_g)
            return
        clock = self._clock = self._clock + dt_s
        g0, g1, g2 = gyro_dps  # written out (runs at every sample): the same sums and comparisons as a loop
        sm, lo, hi = self._sum, self._lo, self._hi
        sm[0] += g0
        sm[1] += g1
        sm[2] += g2
        if g0 < lo[0]:
            lo[0] = g0
        if g0 > hi[0]:
            hi[0] = g0
        if g1 < lo[1]:
            lo[1] = g1
        if g1 > hi[1]:
            hi[1] = g1
        if g2 < lo[2]:
            lo[2] = g2
        if g2 > hi[2]:
            hi[2] = g2
        if abs(accel_g_norm - 1.0) > 0.15:
            self._accel_ok = False
        self._n += 1
        self._t += dt_s
        spread = hi[0] - lo[0]  # max() of the three
        d = hi[1] - lo[1]
        if d > spread:
            spread = d
        d = hi[2] - lo[2]
        if d > spread:
            spread = d
        if spread > 2.0 * self.still_dps or not self._accel_ok:
            self._start()
            self._pending = self._long = None
            return
        if accel_g is not None and type(accel_g) is not tuple:
            accel_g = tuple(accel_g)
        if mag_uT is not None and type(mag_uT) is not tuple:
            mag_uT = tuple(mag_uT)
        for acc, mag in ((self._acc, self._mag), self._long) if self._long is not None else ((self._acc, self._mag),):
            if accel_g is not None:
                acc.add(clock, accel_g)
            if mag_uT is not None:
                mag.add(clock, mag_uT)
        if self._t >= self.still_time_s:
            self._end_window()

    def run_deferred(self) -> None:
        """The sample an ``add(..., defer=True)`` left (nothing if none)."""
        queued, self._queued = self._queued, None
        if queued is not None:
            self.add(*queued)

    def _end_window(self) -> None:
        mean = [s / self._n for s in self._sum]
        acc, mag = self._acc, self._mag
        still = not acc.moved(self.ACCEL_FLOOR_G) and not mag.moved(MAG_STILL_UT)
        confirmed = mag.n >= 0.5 * self._n
        self._start()
        if not still or max(abs(m) for m in mean) > self.MAX_BIAS_DPS:
            self._pending = self._long = None
            return
        if self.updates == 0 or (confirmed and not self.confirmed):
            self._accept(mean, confirmed, replace=True)
            return
        tol = self.base_dps + self.drift_dps_per_s * (self._clock - self._last_update_s)
        if max(abs(m - b) for m, b in zip(mean, self.bias)) <= tol:
            self._accept(mean, confirmed, replace=False)
            return
        pending, long = self._pending, self._long
        if (pending is not None and max(abs(m - p) for m, p in zip(mean, pending[0])) <= self.base_dps
                and not long[0].moved(self.ACCEL_FLOOR_G) and not long[1].moved(MAG_STILL_UT)):
            self._accept([0.5 * (m + p) for m, p in zip(mean, pending[0])], confirmed and pending[1], replace=True)
            return
        self.rejected += 1
        self._pending = (mean, confirmed)
        self._long = (acc, mag)  # the trends go on over the next window

    def _accept(self, mean, confirmed: bool, replace: bool) -> None:
        # agreeing windows are averaged (the last AVERAGE_WINDOWS weigh most: the noise of the mean shrinks,
        # a drifting bias is still followed); a replacement starts the average again
        self._windows = 1 if replace else min(self._windows + 1, self.AVERAGE_WINDOWS)
        k = 1.0 / self._windows
        self.bias = [b + k * (m - b) for b, m in zip(self.bias, mean)]
        self.updates += 1
        self.confirmed = confirmed or (self.confirmed and not replace)
        self._last_update_s = self._clock
        self._pending = self._long = None


def up_from_quat(q):
    """The earth's up (z) expressed in sensor coordinates, for a sensor-to-earth quaternion (w, x, y, z)."""
    w, x, y, z = q
    return (2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y))


def body_rate_dps(q0, q1, dt_s: float):
    """Angular rate (°/s, sensor axes) that turns orientation q0 into q1 in dt_s: from q0* ⊗ q1."""
    w0, x0, y0, z0 = q0
    w1, x1, y1, z1 = q1
    # d = conj(q0) ⊗ q1
    w = w0 * w1 + x0 * x1 + y0 * y1 + z0 * z1
    x = w0 * x1 - x0 * w1 - y0 * z1 + z0 * y1
    y = w0 * y1 + x0 * z1 - y0 * w1 - z0 * x1
    z = w0 * z1 - x0 * y1 + y0 * x1 - z0 * w1
    if w < 0:
        w, x, y, z = -w, -x, -y, -z
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12 or dt_s <= 0:
        return (0.0, 0.0, 0.0)
    angle = 2.0 * math.atan2(s, w)
    k = math.degrees(angle) / (s * dt_s)
    return (x * k, y * k, z * k)


_ENU_TO_NWU = quaternion.conj(quaternion.Q_NWU_TO_ENU)


class _NwuFilter:
    """Adapts an ENU filter (sphere.fusion's SphereFilter) to the NWU quaternions the protocol and the
    stream use: q_NWU = q_ENU→NWU ⊗ q_ENU."""

    def __init__(self, inner):
        self.inner = inner

    def update(self, *args, **kwargs):
        q = self.inner.update(*args, **kwargs)  # defer_bias passes through to SphereFilter
        if type(q) is not tuple or type(q[0]) is not float:  # SphereFilter's own: a tuple of floats
            q = tuple(float(v) for v in q)
        return quaternion.mul(_ENU_TO_NWU, q)

    @property
    def quat(self):
        return quaternion.mul(_ENU_TO_NWU, tuple(float(v) for v in self.inner.quat))

    @quat.setter
    def quat(self, q):  # SphereFilter initialises itself from its first samples
        pass


def host_filter(name: str = "auto", beta: float | None = 0.1, dt_s: float = 0.005):
    """The host fusion filter by its name in ``sphere.fusion.registry`` (the filters it marks live: ``vqf``, the
    default, ``sphere`` and ``madgwick``), or ``auto`` = the first of them that is installed. Built by the registry
    with its defaults, so the daemon runs the same settings as `sphere eval`; ``beta`` (when not None) replaces
    Madgwick's; ``dt_s`` is the sample step for a filter built for a fixed rate (VQF). None when sphere.fusion is
    not installed. Returns NWU quaternions."""
    try:
        from sphere.fusion import registry
    except ImportError:  # the daemon works without the fusion package (device orientation only)
        return None
    known = registry.live_available()
    if name == "auto":
        name = known[0]
    if name not in known:
        missing = " (its package is not installed: pip install 'marg-sphere[daemon]')" if name in registry.LIVE else ""
        raise ValueError(f"unknown host filter {name!r}{missing}; known: auto, {', '.join(known)}")
    f = registry.make(name, dt_s, **({"beta": beta} if name == "madgwick" and beta is not None else {}))
    return f if f.earth_frame == "NWU" else _NwuFilter(f)


class MotionTracker:
    """Feed packets in; read ``gyro_dps`` (bias-corrected, sensor axes), ``up`` and ``quat`` (sensor-to-NWU)."""

    def __init__(self, orientation_source: str = "auto", use_mag: bool = False, beta: float = 0.1,
                 bias: GyroBias | None = None, imu_rate_hz: float = 200.0, filter_name: str = "auto"):
        self.bias = bias or GyroBias()
        self.orientation_source = orientation_source
        self.use_mag = use_mag
        self.filter = None
        if orientation_source in ("auto", "host"):
            self.filter = host_filter(filter_name, beta, 1.0 / imu_rate_hz)
        inner = getattr(self.filter, "inner", self.filter)
        # the work that may wait until the sample's pointer move is out: SphereFilter's bias step (every 10th
        # sample) and GyroBias's still detection (but on a window's last sample); ``raw()`` leaves it, the daemon calls run_deferred() after the move
        # (bit-identical to doing it inside). Off by default: a caller that sets ``defer = True`` calls
        # run_deferred() after each raw() (the daemon does).
        self._filter_deferred = getattr(inner, "run_deferred", None)
        self._defer = {"defer_bias": True} if self._filter_deferred is not None else {}
        self.defer = False
        self.quat = None  # (w, x, y, z) sensor-to-NWU, or None until known
        self.up = None  # earth up in sensor axes
        self.accel_g = None  # the last RAW_SAMPLE's acceleration (g, sensor axes) when the chip answered
        self.gyro_dps = (0.0, 0.0, 0.0)
        self.default_dt_s = 1.0 / imu_rate_hz
        self._last_raw_t = None
        self._last_ori_t = None
        self._accel_up = None
        self._filter_started = False
        self.raw_seen = False

    @property
    def uses_host_filter(self) -> bool:
        return self.filter is not None and self.raw_seen

    def reset_time(self) -> None:
        """After a reconnect: the next sample starts a new time base."""
        self._last_raw_t = None
        self._last_ori_t = None

    def _dt(self, t_us, last):
        if t_us is None or last is None:
            return self.default_dt_s
        dt = (t_us - last) * 1e-6
        if dt <= 0.0 or dt > 0.1:
            return self.default_dt_s
        return dt

    def raw(self, sample, t_us) -> float:
        """Take a RAW_SAMPLE; returns its dt in seconds."""
        self.raw_seen = True
        dt = self._dt(t_us, self._last_raw_t)
        self._last_raw_t = t_us
        s = _GYRO_DPS_PER_LSB
        g = sample.gyro
        gyro = (g[0] * s, g[1] * s, g[2] * s)
        a = sample.accel
        ka = _ACCEL_G_PER_LSB
        ax, ay, az = a[0] * ka, a[1] * ka, a[2] * ka
        anorm = math.sqrt(ax * ax + ay * ay + az * az)
        flags = sample.flags
        self.accel_g = (ax, ay, az) if flags & RAW_ACCEL_OK else None
        if flags & (RAW_GYRO_OK | RAW_GYRO_STALE) != RAW_GYRO_OK:
            # gyro_ok clear (spec §4.2: the chip did not answer, its values are 0) or gyro_stale set (a value held
            # from the last good read): not a rate. Nothing moves, nothing is learnt, the orientation holds.
            self.gyro_dps = (0.0, 0.0, 0.0)
            return dt
        tap_active = bool(flags & RAW_TAP_ACTIVE)
        accel_ok = bool(flags & RAW_ACCEL_OK) and anorm > 0.0
        km = _MAG_UT_PER_LSB
        m = sample.mag
        mag_ok = bool(flags & RAW_MAG_OK) and -4096 not in m
        mag = (m[0] * km, m[1] * km, m[2] * km) if mag_ok else None
        if accel_ok and not tap_active:
            self.bias.add(gyro, anorm, dt, mag, (ax, ay, az), self.defer)
        b = self.bias.bias
        self.gyro_dps = (gyro[0] - b[0], gyro[1] - b[1], gyro[2] - b[2])
        if accel_ok and not tap_active and 0.5 < anorm < 1.5:
            # low-passed accelerometer as the vertical when no orientation is known
            if self._accel_up is None:
                self._accel_up = (ax / anorm, ay / anorm, az / anorm)
            else:
                k = 0.05
                u = self._accel_up
                self._accel_up = (u[0] + k * (ax / anorm - u[0]), u[1] + k * (ay / anorm - u[1]), u[2] + k * (az / anorm - u[2]))
        if self.filter is not None and self.orientation_source != "device":
            if not self._filter_started and accel_ok:
                self._start_filter(ax, ay, az, sample)
            if not self.use_mag:
                mag = None
            gd = self.gyro_dps
            q = self.filter.update((gd[0] * DEG, gd[1] * DEG, gd[2] * DEG), (ax * G_M_S2, ay * G_M_S2, az * G_M_S2),
                                   mag, dt, acc_valid=accel_ok and not tap_active, **(self._defer if self.defer else {}))
            # _NwuFilter gives a tuple of floats (quaternion.mul's); another filter's output is made one
            self.quat = q if type(q) is tuple and type(q[0]) is float else tuple(float(v) for v in q)
            self.up = up_from_quat(self.quat)
        elif self.quat is None:
            self.up = self._accel_up
        return dt

    def run_deferred(self) -> None:
        """What the last ``raw()`` left for after the move (see ``defer``)."""
        if self.bias._queued is not None:
            self.bias.run_deferred()
        if self._filter_deferred is not None:
            self._filter_deferred()

    def _start_filter(self, ax, ay, az, sample) -> None:
        """Start the host filter at the accelerometer's tilt (no slow convergence from identity)."""
        self._filter_started = True
        try:
            from sphere.fusion.common import ecompass

            self.filter.quat = ecompass(ax, ay, az, None, None, None, frame="NWU")
        except Exception:
            pass

    def orientation(self, packet, t_us) -> float:
        """Take an ORIENTATION packet; returns its dt in seconds. Ignored while the host filter runs."""
        dt = self._dt(t_us, self._last_ori_t)
        self._last_ori_t = t_us
        if self.uses_host_filter and self.orientation_source != "device":
            return dt
        q = packet.quat_float
        n = math.sqrt(sum(v * v for v in q))
        if n > 0:
            q = tuple(v / n for v in q)
            if not self.raw_seen:
                # an orientation-only stream (a slow Bluetooth link): the rate from successive orientations
                self.gyro_dps = body_rate_dps(self.quat, q, dt) if self.quat is not None else (0.0, 0.0, 0.0)
            self.quat = q
            self.up = up_from_quat(self.quat)
        return dt
