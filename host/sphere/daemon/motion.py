"""What the sphere is doing now, from its packets: bias-corrected angular rate, the vertical, orientation.

RAW_SAMPLE gyro values are uncalibrated chip units (14.375 LSB per °/s). The bias comes from the host's one
owner of it, :class:`sphere.daemon.gyro_bias.GyroBias` (learnt lying still and held in the hand); the
pointer, the host's fusion filter (``sphere.fusion``, fed the corrected rate) and so the stream all use it.
Orientation comes from that filter, or from the firmware's ORIENTATION packets (Q14, sensor-to-NWU).
"""

from __future__ import annotations

import math

from sphere import chips
from sphere import quaternion
from sphere.daemon.gyro_bias import GyroBias, RestHold
from sphere.fusion import registry
from sphere.fusion import factory
from sphere.fusion.common import ecompass
from sphere.protocol.packets import RAW_ACCEL_OK, RAW_GYRO_OK, RAW_GYRO_STALE, RAW_MAG_OK, RAW_TAP_ACTIVE

__all__ = ["GyroBias", "MotionTracker", "body_rate_dps", "host_filter", "up_from_quat"]

G_M_S2 = chips.STANDARD_GRAVITY_M_S2
DEG = math.pi / 180.0
_GYRO_DPS_PER_LSB = 1.0 / chips.ITG3200_LSB_PER_DPS
_ACCEL_G_PER_LSB = 1.0 / chips.ADXL345_LSB_PER_G
_MAG_UT_PER_LSB = 1.0 / chips.HMC5883L_LSB_PER_UT
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


def host_filter(name: str = "auto", settings=None, dt_s: float = 0.005, **overrides):
    """The host fusion filter by its name in ``sphere.fusion.registry`` (the filters it marks live: ``sphere``, the
    default, ``vqf`` and ``madgwick``), or ``auto`` = the first of them that is installed. Built by the registry
    from its PARAMS, so the daemon runs the same settings as `sphere eval`: ``settings(section)`` gives its
    ``[orientation.NAME]`` values (the daemon passes ``cfg.get``), ``overrides`` replace single ones; ``dt_s`` is
    the sample step for a filter built for a fixed rate (VQF, which then follows the step the samples give). Returns
    NWU quaternions."""
    known = registry.live_available()
    if name == "auto":
        name = known[0]
    if name not in known:
        missing = " (its package is not installed: pip install 'marg-sphere[daemon]')" if name in registry.LIVE else ""
        raise ValueError(f"unknown host filter {name!r}{missing}; known: auto, {', '.join(known)}")
    given = settings(registry.REGISTRY.section(name)) if settings is not None else None
    f = factory.make(name, dt_s, **{**(given.as_dict() if given is not None else {}), **overrides})
    return f if f.earth_frame == "NWU" else _NwuFilter(f)


class MotionTracker:
    """Feed packets in; read ``gyro_dps`` (bias-corrected, sensor axes), ``up`` and ``quat`` (sensor-to-NWU)."""

    def __init__(self, orientation_source: str = "auto", use_mag: bool = False, bias: GyroBias | None = None,
                 imu_rate_hz: float = 200.0, filter_name: str = "auto", rest_hold: RestHold | None = None,
                 filter_settings=None):
        """``filter_settings(section)``: the host filter's ``[orientation.NAME]`` settings (see host_filter)."""
        self.bias = bias or GyroBias()
        self.rest_hold = rest_hold or RestHold()
        self.orientation_source = orientation_source
        self.use_mag = use_mag
        self.filter = None
        if orientation_source in ("auto", "host"):
            self.filter = host_filter(filter_name, filter_settings, 1.0 / imu_rate_hz)
        inner = getattr(self.filter, "inner", self.filter)
        # the work that may wait until the sample's pointer move is out: the host filter's update (the orientation,
        # ``quat`` and ``up``), SphereFilter's bias step (every 10th sample) and GyroBias's still detection (but on
        # a window's last sample). With ``defer = True`` ``raw()`` leaves them; the caller runs update_orientation()
        # before it reads ``quat`` and run_deferred() after the move (the daemon does). Meanwhile ``up`` (the
        # vertical the pointer's mapping uses) is the last sample's turned by this sample's rate. Off by default:
        # ``raw()`` then does everything itself, as before.
        self._filter_deferred = getattr(inner, "run_deferred", None)
        self._defer = {"defer_bias": True} if self._filter_deferred is not None else {}
        self.defer = False
        self._pending = None  # the filter update raw() left: its inputs (update_orientation)
        self.quat = None  # (w, x, y, z) sensor-to-NWU, or None until known
        self.up = None  # earth up in sensor axes
        self.accel_g = None  # the last RAW_SAMPLE's acceleration (g, sensor axes) when the chip answered
        self.gyro_dps = (0.0, 0.0, 0.0)
        self.pointer_dps = (0.0, 0.0, 0.0)  # gyro_dps for the pointer: zero while the rest hold holds it
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
        if self._pending is not None:  # a caller that deferred and did not come back: the last sample's first
            self.update_orientation()
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
            self.gyro_dps = self.pointer_dps = (0.0, 0.0, 0.0)
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
        self.pointer_dps = self.rest_hold(self.gyro_dps, dt, self.bias.still_s, self.bias.still_dps)
        if accel_ok and not tap_active and 0.5 < anorm < 1.5:
            # low-passed accelerometer as the vertical when no orientation is known
            if self._accel_up is None:
                self._accel_up = (ax / anorm, ay / anorm, az / anorm)
            else:
                k = 0.05
                u = self._accel_up
                self._accel_up = (u[0] + k * (ax / anorm - u[0]), u[1] + k * (ay / anorm - u[1]), u[2] + k * (az / anorm - u[2]))
        if self.filter is not None and self.orientation_source != "device":
            gd = self.gyro_dps
            self._pending = (gd, ax, ay, az, mag if self.use_mag else None, dt, accel_ok,
                             accel_ok and not tap_active)
            if not self.defer:
                self.update_orientation()
            elif self.up is not None:
                # until the filter's update: the last vertical turned by this sample's rate (what the filter's
                # own prediction step does; its accelerometer correction comes with the update). The vertical is
                # fixed in the world, so in the sensor's axes it turns against the sensor: d(up)/dt = up × ω.
                ux, uy, uz = self.up
                k = dt * DEG
                wx, wy, wz = gd[0] * k, gd[1] * k, gd[2] * k
                self.up = (ux + uy * wz - uz * wy, uy + uz * wx - ux * wz, uz + ux * wy - uy * wx)
        elif self.quat is None:
            self.up = self._accel_up
        return dt

    def update_orientation(self) -> None:
        """The host filter's update for the last ``raw()``, when it was left (``defer``): ``quat`` and ``up`` are
        then this sample's. Nothing when there is none pending."""
        pending = self._pending
        if pending is None:
            return
        self._pending = None
        gd, ax, ay, az, mag, dt, accel_ok, acc_valid = pending
        if not self._filter_started and accel_ok:
            self._start_filter(ax, ay, az)
        q = self.filter.update((gd[0] * DEG, gd[1] * DEG, gd[2] * DEG), (ax * G_M_S2, ay * G_M_S2, az * G_M_S2),
                               mag, dt, acc_valid=acc_valid, **(self._defer if self.defer else {}))
        # _NwuFilter gives a tuple of floats (quaternion.mul's); another filter's output is made one
        self.quat = q if type(q) is tuple and type(q[0]) is float else tuple(float(v) for v in q)
        self.up = up_from_quat(self.quat)

    def run_deferred(self) -> None:
        """What the last ``raw()`` left for after the move (see ``defer``)."""
        if self._pending is not None:
            self.update_orientation()
        if self.bias._queued is not None:
            self.bias.run_deferred()
        if self._filter_deferred is not None:
            self._filter_deferred()

    def _start_filter(self, ax, ay, az) -> None:
        """Start the host filter at the accelerometer's tilt (no slow convergence from identity)."""
        self._filter_started = True
        if ax or ay or az:  # a reading of 0 has no tilt: the filter starts level and finds it
            self.filter.quat = ecompass(ax, ay, az, None, None, None, frame="NWU")

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
                self.pointer_dps = self.gyro_dps
            self.quat = q
            self.up = up_from_quat(self.quat)
        return dt
