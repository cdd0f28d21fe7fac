"""From motion to pointer motion: the pure core of sphere-mouse (no device, no clock, no I/O).

:class:`PointerMapper` turns angular rate into pixels the way the best gyro-mouse software does
(JoyShockMapper's gyro settings are the model):

1. **Axes.** ``world`` axes take yaw about the *vertical* (from gravity) and pitch about the horizontal
   axis across the pointing direction, so the pointer moves the same way however the sphere is rolled
   in the hand; ``local`` axes take the sensor's own z (yaw) and y (pitch). Sensor frame: x forward
   (towards the screen), y left, z up when the sphere sits in its nominal pose.
2. **Smoothing** from the registry of :mod:`sphere.smoothing` (``smoothing``, default ``tremor``: a
   band-stop for the hand's 8–12 Hz tremor that lets fast moves through untouched; ``tiered`` is
   JoyShockMapper's soft tiered smoothing). The filter runs on the pointer's angles in degrees (the
   integral of the screen rates) and the rate is taken back from its output, so every filter of the
   registry fits here and the pointer shows exactly what the filter outputs.
3. **Tightening** of the smoothed rate. Below ``tightening_dps`` the rate is scaled by
   ``rate/tightening_dps``: what is left of noise and tremor at rest shrinks quadratically but slow
   deliberate motion still moves the pointer (no hard dead zone).
4. **Sensitivity in real-world terms** (degrees of rotation per screen width) with optional
   **acceleration**: the slow sensitivity up to ``accel_low_dps``, the fast one from ``accel_high_dps``,
   blended linearly between them.
5. **Hand hold.** Held in the hand between moves, the pointer stays where it is once the smoothed rate has
   settled (``hold_*``): the ITG-3200's noise and the hand's slow sway would creep it by several px/s after
   every stop, which tightening alone does not stop. A move, or a slow steady aim, ends the hold and brings
   what was held back of it at once; a single sample far above what the held hand's tremor reaches
   (``hold_pass_*``) moves the pointer at once, so a sharp move is not a sample late.
6. **Sub-pixel remainders** carry over to the next sample, so slow motion is not lost to rounding; a whole pixel
   is stepped once the remainder reaches ``step_at_px`` (0.8: the shown pointer trails a slow move by 0.3 px on
   average instead of half a pixel, and a quiver under 0.6 px does not move it).

:class:`TiltMapper` makes the tilt from a recentred pose drive pointer *velocity*.
"""

from __future__ import annotations

import math
from collections import deque

from sphere.settings import Param, Settings
from sphere.smoothing.registry import DEFAULT as DEFAULT_SMOOTHING
from sphere.smoothing.registry import REGISTRY as SMOOTHING
from sphere.smoothing.registry import make_filter

#: the ``[pointer]`` section: :class:`PointerMapper`'s parameters
POINTER_PARAMS = {
    "slow_deg_per_width": Param(40.0, doc="degrees of wrist rotation that move the pointer one screen width when "
                                       "turning slowly (below `accel_low_dps`)", lo=0.5, hi=3600.0),
    "fast_deg_per_width": Param(40.0, doc="the same when turning fast (above `accel_high_dps`); smaller than "
                                       "`slow_deg_per_width` = acceleration; equal = none", lo=0.5, hi=3600.0),
    "accel_low_dps": Param(20.0, doc="rotation speed (°/s) up to which the slow sensitivity applies",
        lo=0.0, hi=2000.0),
    "accel_high_dps": Param(120.0, doc="rotation speed (°/s) from which the fast sensitivity applies; between the "
                                   "two it is blended linearly", lo=0.001, hi=5000.0),
    "tightening_dps": Param(1.0, doc="rotations slower than this are scaled down in proportion to their speed "
                                   "(soft, instead of a dead zone that swallows them); 0 = off", lo=0.0, hi=100.0),
    "hold_band_dps": Param(0.8, doc="held in the hand: once the smoothed rate's mean over `hold_window_s` has stayed "
                                    "within this (°/s) for `hold_after_s`, the pointer stays where it is (the "
                                    "sensor's noise and the hand's slow sway do not creep it); the move that leaves "
                                    "the band brings what the window held back at once (0 = off)", lo=0.0, hi=10.0),
    "hold_window_s": Param(0.1, doc="the short mean's length for `hold_band_dps`", lo=0.005, hi=1.0),
    "hold_after_s": Param(0.15, doc="how long the short mean must have stayed within `hold_band_dps` before the "
                                   "pointer is held (the end of a move comes through the smoothing first)",
        lo=0.0, hi=10.0),
    "hold_slow_dps": Param(0.3, doc="a slow steady aim ends the hold too: when the held-back turn over the last "
                                    "`hold_slow_window_s` exceeds this rate (°/s) times that window, it comes at once "
                                    "and the pointer follows", lo=0.0, hi=10.0),
    "hold_slow_window_s": Param(1.0, doc="the window of `hold_slow_dps`", lo=0.005, hi=5.0),
    "hold_pass_dps": Param(4.0, doc="while held, a single sample whose smoothed rate exceeds this (°/s) and "
                                    "`hold_pass_spread` times the held rate's RMS moves the pointer at once, so a sharp "
                                    "move's first sample is not kept back until the short mean leaves the band; what "
                                    "the hold kept back comes when the hold ends (0 = off)", lo=0.0, hi=100.0),
    "hold_pass_spread": Param(6.0, doc="`hold_pass_dps` in the held hand's own units: the smoothed rate's RMS over "
                                       "the held samples (time constant `hold_slow_window_s`: the tremor and noise this "
                                       "hand shows) times this must be exceeded too; 0 = `hold_pass_dps` alone",
        lo=0.0, hi=100.0),
    "step_at_px": Param(0.8, doc="the pointer steps a whole pixel once what has built up below a pixel reaches this "
                                 "(px, either way): 1 = only whole pixels (the shown pointer trails the motion by half "
                                 "a pixel on average, 3.5 ms in a 3 °/s aim), 0.5 = the nearest pixel; what lies below "
                                 "steps back only past the same threshold the other way, so a sub-pixel quiver of "
                                 "2 × this − 1 px does not move it", lo=0.5, hi=1.0),
    "gyro_lowpass_hz": Param(98.0, doc="the gyro chip's own low-pass as the firmware sets it (ITG-3200 DLPF_CFG 2: "
                                       "98 Hz at its 1 kHz internal rate, firmware 0.3.2; 42 before): its ringing "
                                       "after a hard stop is turned into a critically damped response before the "
                                       "pointer sees it, so a stop does not overshoot (0 = off)", lo=0.0, hi=256.0),
    "smoothing": Param(DEFAULT_SMOOTHING, doc="smoothing filter of the pointer, from the smoothing registry (its "
                                              "parameters in [smoothing.NAME]); `tremor` takes out the hand's 8–12 "
                                              "Hz tremor, `none` = off", choices=lambda: tuple(SMOOTHING)),
    "axes": Param("world", doc="`world`: turning about the vertical moves the pointer sideways however the sphere is "
                               "rolled (uses gravity); `local`: the sensor's own z (yaw) and y (pitch) axes",
        choices=("world", "local")),
    "invert_x": Param(False, doc="swap left and right"),
    "invert_y": Param(False, doc="swap up and down"),
}


class PointerSettings(Settings):
    """:class:`PointerMapper`'s settings: ``PointerSettings(axes="local")``, the defaults for the rest."""

    def __init__(self, **values):
        super().__init__(POINTER_PARAMS, values)


def _norm3(v):
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


def screen_rates_dps(gyro_dps, up_body, axes: str, last_forward=None):
    """(yaw, pitch) in °/s: yaw positive turning left, pitch positive tipping the nose down.

    ``up_body`` is the vertical (up) expressed in sensor coordinates, or None (then local axes).
    Returns (yaw, pitch, forward) where forward is the horizontal pointing direction used (world axes).
    """
    wx, wy, wz = gyro_dps
    if axes == "local" or up_body is None:
        return wz, wy, last_forward
    ux, uy, uz = up_body
    n = math.sqrt(ux * ux + uy * uy + uz * uz)
    if n < 1e-9:
        return wz, wy, last_forward
    ux, uy, uz = ux / n, uy / n, uz / n
    yaw = wx * ux + wy * uy + wz * uz
    # forward: sensor x made horizontal; when x points (nearly) straight up or down keep the last one
    fx, fy, fz = 1.0 - ux * ux, -ux * uy, -ux * uz
    fn = math.sqrt(fx * fx + fy * fy + fz * fz)
    if fn < 0.2:
        if last_forward is None:
            return wz, wy, last_forward
        fx, fy, fz = last_forward
    else:
        fx, fy, fz = fx / fn, fy / fn, fz / fn
    # left = up × forward
    lx, ly, lz = uy * fz - uz * fy, uz * fx - ux * fz, ux * fy - uy * fx
    pitch = wx * lx + wy * ly + wz * lz
    return yaw, pitch, (fx, fy, fz)


def _check_pointer(s):
    if s.accel_high_dps <= s.accel_low_dps:
        return f"accel_high_dps = {s.accel_high_dps} must be greater than accel_low_dps = {s.accel_low_dps}"
    return None


class _HoldWindow:
    """The last ``length_s`` of the smoothed rate's displacement (°), and of the pointer's held-back px."""

    __slots__ = ("rows", "sums")

    def __init__(self):
        self.rows = deque()  # [smoothed x·dt, y·dt, dt, held-back px x, y]
        self.sums = [0.0, 0.0, 0.0, 0.0, 0.0]

    def add(self, ax: float, ay: float, dt_s: float, length_s: float) -> None:
        rows, sums = self.rows, self.sums
        rows.append([ax, ay, dt_s, 0.0, 0.0])
        sums[0] += ax
        sums[1] += ay
        sums[2] += dt_s
        while len(rows) > 1 and sums[2] - rows[0][2] >= length_s - 1e-9:
            old = rows.popleft()
            for i in range(5):
                sums[i] -= old[i]

    def within(self, band_dps: float) -> bool:
        """Whether the window's mean rate is within ``band_dps``."""
        return self.turned_within(band_dps * self.sums[2])

    def turned_within(self, limit_deg: float) -> bool:
        """Whether the window's turn (its displacement, °) is within ``limit_deg``."""
        return self.sums[0] * self.sums[0] + self.sums[1] * self.sums[1] <= limit_deg * limit_deg

    def held(self, fx: float, fy: float) -> None:
        row = self.rows[-1]
        row[3], row[4] = fx, fy
        self.sums[3] += fx
        self.sums[4] += fy

    def clear(self) -> None:
        self.rows.clear()
        self.sums[:] = [0.0] * 5

    def release(self) -> None:
        for row in self.rows:
            row[3] = row[4] = 0.0
        self.sums[3] = self.sums[4] = 0.0


class LowpassEqualizer:
    """Per axis, the gyro chip's low-pass turned into a critically damped one at the same corner.

    The ITG-3200 filters its rate at 1 kHz with the DLPF_CFG bandwidth (datasheet §8.3, register 22 gives the
    bandwidth only; InvenSense's MPU-6000/6050 register map gives the same filter's delays, register 26); the
    virtual board models it as a second-order Butterworth (bilinear, prewarped), whose step response overshoots
    by 4 %: after a hard stop at 200 °/s the rate swings the other way for a few ms (at 42 Hz 4–6 °/s for about
    10 ms, 2–3 px back at 48 px/°; at 98 Hz about half that). The samples the host reads (every ``dt_s``) follow the same two poles, raised
    to the power ``dt_s`` × 1 kHz; this filter has zeros on them and a double real pole at exp(−2π·f·``dt_s``),
    with unit gain at 0 Hz: the chip and it together are critically damped (no overshoot), and its own gain is
    at most 1 at every frequency (it never amplifies the noise). Lag added: about 2 ms at 42 Hz, 1 ms at 98."""

    INTERNAL_HZ = 1000.0  # the ITG-3200's internal sample rate with the DLPF on (DLPF_CFG 1-6)

    def __init__(self, corner_hz: float):
        self.corner_hz = corner_hz
        self._coeffs = {}
        self.reset()

    def reset(self, at_rest: bool = False) -> None:
        """Start again: from the next sample as if it had always been so, or (``at_rest``: after lying still) from
        a history of zeros, so that what comes out adds up to what goes in (a rest hold's release carry too)."""
        self._state = None  # per axis [x1, x2, y1, y2]
        self._at_rest = at_rest

    MIN_DT_S = 0.0005  # a shorter step (two samples stamped within half a chip period) is designed as this one

    def _design(self, dt_s: float):
        # at a step of 0 both the zeros and the poles sit at 1 and the 0 Hz gain is 0/0: a burst of samples stamped
        # microseconds apart (a sender that fell behind) must not stop the daemon
        key = max(round(dt_s, 4), self.MIN_DT_S)
        c = self._coeffs.get(key)
        if c is None:
            f, fi = self.corner_hz, self.INTERNAL_HZ
            k = math.tan(math.pi * f / fi)
            norm = 1.0 / (1.0 + math.sqrt(2.0) * k + k * k)
            a1, a2 = 2.0 * (k * k - 1.0) * norm, (1.0 - math.sqrt(2.0) * k + k * k) * norm
            disc = complex(a1 * a1 - 4.0 * a2)
            pole = (-a1 + disc ** 0.5) / 2.0  # one of the conjugate pair
            p = pole ** (key * fi)
            n1, n2 = -2.0 * p.real, abs(p) ** 2
            r = math.exp(-2.0 * math.pi * f * key)
            d1, d2 = -2.0 * r, r * r
            g = (1.0 + d1 + d2) / (1.0 + n1 + n2)
            c = self._coeffs[key] = (g, g * n1, g * n2, d1, d2)
        return c

    def __call__(self, rate, dt_s: float):
        if dt_s <= 0.0 or dt_s > 0.05:  # no steady sample period: start again from this sample
            self._state = None
            return rate
        b0, b1, b2, d1, d2 = self._design(dt_s)
        st = self._state
        if st is None:
            st = self._state = [[0.0] * 4 if self._at_rest else [v, v, v, v] for v in rate]
            self._at_rest = False  # once: a later restart (a gap in the samples) starts from its first sample
        out = []
        for v, s in zip(rate, st):
            y = b0 * v + b1 * s[0] + b2 * s[1] - d1 * s[2] - d2 * s[3]
            s[1], s[0], s[3], s[2] = s[0], v, s[2], y
            out.append(y)
        return tuple(out)


class PointerMapper:
    """Angular rate → integer pointer steps. Feed every gyro sample to :meth:`update`.

    ``screen_width_px`` sets the scale: rotating by ``slow_deg_per_width`` degrees moves the pointer
    by that many pixels.
    """

    NAME = "pointer"
    PARAMS = POINTER_PARAMS

    def __init__(self, settings: Settings | None = None, screen_width_px: int = 1920,
                 smoothing_params: dict | None = None):
        """``settings``: the [pointer] values (:class:`PointerSettings`); ``smoothing_params``: the smoothing
        filter's own (its [smoothing.NAME] section; None = its defaults)."""
        self.settings = settings or PointerSettings()
        self.screen_width_px = int(screen_width_px)
        self.filter = make_filter(self.settings.smoothing, **(smoothing_params or {}))
        lp = self.settings.gyro_lowpass_hz
        self.equalizer = LowpassEqualizer(lp) if lp > 0 else None
        self._forward = None
        self._holding = False
        self.reset()

    check_settings = staticmethod(_check_pointer)

    def reset(self) -> None:
        """Forget smoothing history and sub-pixel remainders (after a pause, a freeze, a mode switch)."""
        self.filter.reset()
        if self.equalizer is not None:
            self.equalizer.reset()
        self._angle = [0.0, 0.0]  # the pointer's angles (°, right and down) fed to the filter
        self._filtered = None
        self.remainder = [0.0, 0.0]
        self._smoothed = (0.0, 0.0)  # the last sample's smoothed rate (°/s, screen right and down)
        self._short = _HoldWindow()  # the hand hold's windows (_hand_hold)
        self._slow = _HoldWindow()
        self._hand_held = False
        self._within_s = 0.0
        self._slow_aim = False  # a slow steady aim ended the hold: followed until its slow mean settles
        self._held_ms = 0.0  # the mean square of the smoothed rate over held samples ((°/s)², hold_pass_spread)

    def rate_px_s(self, gyro_dps, up_body=None, dt_s: float = 0.005):
        """The pointer velocity (px/s, screen x right, y down) for one gyro sample, updating smoothing state."""
        s = self.settings
        yaw, pitch, self._forward = screen_rates_dps(gyro_dps, up_body, s.axes, self._forward)
        # screen degrees/s: right and down positive
        x, y = -yaw, pitch
        # 2. smoothing: the filter runs on the pointer's angles; the rate comes back from its output
        if dt_s <= 0:
            mag = math.hypot(x, y)
        else:
            a = self._angle
            a[0] += x * dt_s
            a[1] += y * dt_s
            out = self.filter.update(a, dt_s)
            last = self._filtered
            self._filtered = (float(out[0]), float(out[1]))
            if last is None:
                last = (a[0] - x * dt_s, a[1] - y * dt_s)
            x, y = (self._filtered[0] - last[0]) / dt_s, (self._filtered[1] - last[1]) / dt_s
            mag = math.hypot(x, y)
        self._smoothed = (x, y)
        # 3. tightening of the smoothed rate (what is left of noise and tremor at rest)
        if s.tightening_dps > 0 and mag < s.tightening_dps:
            k = mag / s.tightening_dps
            x, y = x * k, y * k
        # 4. sensitivity with acceleration
        width = self.screen_width_px
        slow = width / s.slow_deg_per_width
        fast = width / s.fast_deg_per_width
        if slow != fast:
            t = (mag - s.accel_low_dps) / (s.accel_high_dps - s.accel_low_dps)
            t = 0.0 if t < 0.0 else 1.0 if t > 1.0 else t
            px_per_deg = slow + (fast - slow) * t
        else:
            px_per_deg = slow
        vx, vy = x * px_per_deg, y * px_per_deg
        if s.invert_x:
            vx = -vx
        if s.invert_y:
            vy = -vy
        return vx, vy

    def hold(self) -> None:
        """A sample during which the pointer stays where it is (the sphere lies still: the daemon's rest hold):
        no step; the smoothing's history is forgotten once, so the next move starts afresh (no tail of the last
        move comes after the hold); the sub-pixel remainder stays (it is where the pointer is). The hand hold
        takes over from it: when the rest hold lets go while the rate is still within the hand hold's band (its
        still test failing on the window with the stop in it), the pointer stays held."""
        if not self._holding:
            remainder = self.remainder
            self.reset()
            self.remainder = remainder
            self._holding = True
            if self.equalizer is not None:
                self.equalizer.reset(at_rest=True)
            if self.settings.hold_band_dps > 0:
                self._hand_held = True
                self._within_s = self.settings.hold_after_s

    def update(self, gyro_dps, dt_s: float, up_body=None) -> tuple[int, int]:
        """One gyro sample (°/s, sensor axes) over ``dt_s`` seconds → whole-pixel steps (dx right, dy down)."""
        self._holding = False
        if self.equalizer is not None:
            gyro_dps = self.equalizer(gyro_dps, dt_s)
        vx, vy = self.rate_px_s(gyro_dps, up_body, dt_s)
        fx, fy = vx * dt_s, vy * dt_s
        if self.settings.hold_band_dps > 0 and dt_s > 0:
            fx, fy = self._hand_hold(fx, fy, dt_s)
        return self.emit(fx, fy)

    def _hand_hold(self, fx: float, fy: float, dt_s: float) -> tuple[float, float]:
        """The hand hold (the ``hold_*`` settings): no displacement once the smoothed rate's short mean has stayed
        within ``hold_band_dps`` for ``hold_after_s``, as long as it stays there and the turn held back over the
        last ``hold_slow_window_s`` stays under ``hold_slow_dps`` × that window. The sample that ends the hold
        carries what the window it left held back: neither a move's start nor a slow steady aim is lost; a slow
        aim is then followed until its mean over that window has fallen back under ``hold_slow_dps``."""
        s = self.settings
        sx, sy = self._smoothed
        short, slow = self._short, self._slow
        short.add(sx * dt_s, sy * dt_s, dt_s, s.hold_window_s)
        self._within_s = self._within_s + dt_s if short.within(s.hold_band_dps) else 0.0
        limit = s.hold_slow_dps * s.hold_slow_window_s
        if self._slow_aim:
            slow.add(sx * dt_s, sy * dt_s, dt_s, s.hold_slow_window_s)
            if not slow.turned_within(limit):
                return fx, fy
            self._slow_aim = False
        if self._within_s >= s.hold_after_s:
            if not self._hand_held:
                slow.clear()  # the slow aim's test counts from the hold's start, not the move before it
            slow.add(sx * dt_s, sy * dt_s, dt_s, s.hold_slow_window_s)
            if slow.turned_within(limit):
                self._hand_held = True
                if self._passes(sx * sx + sy * sy, dt_s):
                    return fx, fy  # a move's first sample: it moves now, what was held back waits for the release
                short.held(fx, fy)
                slow.held(fx, fy)
                return 0.0, 0.0
            self._slow_aim = True
        if self._hand_held:
            self._hand_held = False
            carry = slow if self._slow_aim else short
            fx, fy = fx + carry.sums[3], fy + carry.sums[4]
            short.release()
            slow.release()
        return fx, fy

    def _passes(self, square: float, dt_s: float) -> bool:
        """Whether a held sample whose smoothed rate squared is ``square`` moves the pointer at once: above
        ``hold_pass_dps`` and ``hold_pass_spread`` times the RMS of the held samples before it (a sample that
        passes does not count in that RMS)."""
        s = self.settings
        if s.hold_pass_dps <= 0:
            return False
        limit = s.hold_pass_dps * s.hold_pass_dps
        if s.hold_pass_spread > 0:
            limit = max(limit, s.hold_pass_spread * s.hold_pass_spread * self._held_ms)
        if square > limit:
            return True
        self._held_ms += min(1.0, dt_s / s.hold_slow_window_s) * (square - self._held_ms)
        return False

    def emit(self, fx: float, fy: float) -> tuple[int, int]:
        """Add a fractional displacement to the remainders and take out whole pixels."""
        r = self.remainder
        r[0] += fx
        r[1] += fy
        # a whole pixel from `step_at_px` on, symmetric for left and right (a hair's allowance so 19.799999999
        # after many small steps of a float sum still gives its 20th pixel)
        t = self.settings.step_at_px - 1e-9
        ix = int(r[0] - t) + 1 if r[0] >= t else -(int(-r[0] - t) + 1) if r[0] <= -t else 0
        iy = int(r[1] - t) + 1 if r[1] >= t else -(int(-r[1] - t) + 1) if r[1] <= -t else 0
        r[0] -= ix
        r[1] -= iy
        return ix, iy


#: the ``[tilt]`` section: :class:`TiltMapper`'s parameters (its left/right and up/down follow [pointer])
TILT_PARAMS = {
    "dead_zone_deg": Param(3.0, doc="tilt from the recentred pose that does not move the pointer", lo=0.0, hi=45.0),
    "full_speed_deg": Param(25.0, doc="tilt at which the pointer reaches `max_speed_px_s`", lo=1.0, hi=90.0),
    "max_speed_px_s": Param(1200.0, doc="pointer speed at full tilt", lo=1.0, hi=100000.0),
    "exponent": Param(1.5, doc="response curve between dead zone and full tilt (1 = linear)", lo=0.5, hi=4.0),
}


class TiltSettings(Settings):
    """:class:`TiltMapper`'s settings: ``TiltSettings(exponent=1.0)``, the defaults for the rest."""

    def __init__(self, **values):
        super().__init__(TILT_PARAMS, values)


def _check_tilt(s):
    if s.full_speed_deg <= s.dead_zone_deg:
        return f"full_speed_deg = {s.full_speed_deg} must be greater than dead_zone_deg = {s.dead_zone_deg}"
    return None


def pointing_angles_deg(quat):
    """Heading (° about the vertical, positive left) and elevation (° up) of the sensor x axis in the earth frame."""
    w, x, y, z = quat
    # first column of the rotation matrix: sensor x in earth coordinates
    fx = 1.0 - 2.0 * (y * y + z * z)
    fy = 2.0 * (x * y + w * z)
    fz = 2.0 * (x * z - w * y)
    heading = math.degrees(math.atan2(fy, fx))
    elevation = math.degrees(math.asin(max(-1.0, min(1.0, fz))))
    return heading, elevation


class TiltMapper:
    """Orientation relative to a recentred pose → pointer velocity; :meth:`update` per orientation sample."""

    NAME = "tilt"
    PARAMS = TILT_PARAMS
    check_settings = staticmethod(_check_tilt)

    def __init__(self, settings: Settings | None = None, invert_x: bool = False, invert_y: bool = False):
        """``settings``: the [tilt] values (:class:`TiltSettings`); ``invert_x``/``invert_y``: [pointer]'s."""
        self.settings = settings or TiltSettings()
        self.invert_x, self.invert_y = invert_x, invert_y
        self.reference = None  # (heading, elevation) of the recentred pose
        self.remainder = [0.0, 0.0]

    def recentre(self, quat) -> None:
        self.reference = pointing_angles_deg(quat)
        self.remainder = [0.0, 0.0]

    def _speed(self, angle_deg: float) -> float:
        s = self.settings
        a = abs(angle_deg)
        if a <= s.dead_zone_deg:
            return 0.0
        t = min(1.0, (a - s.dead_zone_deg) / (s.full_speed_deg - s.dead_zone_deg))
        return math.copysign(s.max_speed_px_s * t ** s.exponent, angle_deg)

    def velocity_px_s(self, quat) -> tuple[float, float]:
        if self.reference is None:
            self.recentre(quat)
        heading, elevation = pointing_angles_deg(quat)
        dh = (heading - self.reference[0] + 180.0) % 360.0 - 180.0
        de = elevation - self.reference[1]
        vx = -self._speed(dh)  # turned left → pointer goes left
        vy = -self._speed(de)  # nose up → pointer goes up
        if self.invert_x:
            vx = -vx
        if self.invert_y:
            vy = -vy
        return vx, vy

    def update(self, quat, dt_s: float) -> tuple[int, int]:
        vx, vy = self.velocity_px_s(quat)
        r = self.remainder
        r[0] += vx * dt_s
        r[1] += vy * dt_s
        ix, iy = int(r[0]), int(r[1])
        r[0] -= ix
        r[1] -= iy
        return ix, iy
