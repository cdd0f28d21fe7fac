"""The host's gyro bias — its one owner. Everything on the host that turns a RAW_SAMPLE's gyro into a rate
takes it from here: the pointer, the host's orientation filter (fed the corrected rate: a filter that learns a
bias of its own learns only what is left) and, through that filter, the 3-D stream and every output.

RAW_SAMPLE gyro values are the chip's own (protocol/spec.md §4.2): the firmware's bias is applied only to its
own ORIENTATION. :class:`GyroBias` learns from two kinds of window, each judged by what a turn cannot fake:

- **lying still** (``still_time_s``): every gyro axis within ±``still_dps`` of the window's middle (hand tremor
  fails this), the accelerometer's magnitude near 1 g and its direction without a trend, the magnetometer's
  field (when it answers) without a trend — a turn about any axis but the vertical tips gravity, a turn about
  the vertical swings the field (``_Trend.moved``: the fitted change over the window against 4 standard errors
  of the slope and one LSB). The window's mean is then the bias to the ITG-3200's noise (its rate noise spectral
  density, datasheet §3.1: about 0.02 °/s over 1 s);
- **held in the hand** (``held_time_s``): tremor moves the gyro by several °/s, so it is judged on the *intent*:
  the rate averaged over 0.25-s blocks and then over 1 s (zeros at 4, 8 and 12 Hz: the 8–12 Hz tremor is
  cut to a few percent) stays within ±``held_dps`` of its window's middle (an aim leaves it), and the
  accelerometer and compass show no trend over the window. The window's mean is the bias up to the hand's
  wander over the window (``held_sigma_dps``). Until a bias is known, held windows are half as long.

A window's mean ``m`` updates the estimate ``b`` as a Kalman filter per axis on the bias and its steady drift:
the bias wanders as a random walk of ``drift_dps`` per √s and its drift rate (the ITG-3200's warm-up moves it by
tenths of a °/s over minutes) as one of ``ramp_dps2``, so a ramp is followed without lag and a window may move
``b`` only as far as the time since the last update allows — a window whose ``m`` is more than ``gate_sigma``
standard deviations from the prediction is no bias (a slow steady aim, a turn the tests could not see) and is
held back.

**Start-up** (no bias known yet): a first window is taken when the compass confirmed it still or when every
axis's mean is within ±``prior_dps`` (what a calibrated chip leaves). A larger mean, with no compass, is what a
steady turn about the vertical looks like — nothing in one window tells them apart — so it must *persist*:
still windows that agree with each other for ``persist_s`` in a row, never broken by motion. A turn stops; a
bias does not. The same rule replaces an estimate later contradicted by lying still for ``persist_s``, and a
compass-confirmed window replaces an unconfirmed estimate at once.

The firmware's own bias (STATUS ``gyro_bias_valid``, its EEPROM calibration) is not used: the RAW_SAMPLE the
host reads does not carry it, and a SET_CALIBRATION changes only the firmware's ORIENTATION.
"""

from __future__ import annotations

import math

from sphere.settings import Param, resolve

MAG_STILL_UT = 0.2  # µT per still window: the compass trend test's floor (HMC5883L noise ≈ 0.2 µT, 1 LSB 0.09 µT)
#: ITG-3200 datasheet (PS-ITG-3200A-00-01.4) §3.1 Sensor Specifications: rate noise spectral density
ITG3200_NOISE_DPS_RT_HZ = 0.03
BLOCK_S = 0.25  # the held window's first average (zeros at 4, 8, 12 Hz)
BLOCKS = 4  # ... then over this many blocks (1 s: zeros at every 1 Hz)


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
        x0, x1, x2 = v  # written out: this runs for every sample
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


class _Window:
    """One window's sums: the gyro's mean and spread, the accelerometer's magnitude, both trends."""

    __slots__ = ("n", "t", "sum", "lo", "hi", "accel_ok", "acc", "mag")

    def __init__(self):
        self.n = 0
        self.t = 0.0
        self.sum = [0.0, 0.0, 0.0]
        self.lo = [math.inf] * 3
        self.hi = [-math.inf] * 3
        self.accel_ok = True
        self.acc = _Trend()
        self.mag = _Trend()

    def spread(self) -> float:
        lo, hi = self.lo, self.hi
        return max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2])

    def mean(self):
        n = self.n
        return [s / n for s in self.sum]


class GyroBias:
    """Gyro bias in °/s (sensor axes): the host's one estimate, learnt lying still and held (module doc)."""

    NAME = "gyro_bias"  # its [gyro_bias] section (the PARTS line in daemon/config.py)
    PARAMS = {
        "held_time_s": Param(3.0, "s", 0.0, 60.0, "length of a held window (in the hand, the intent still); 0 = learn only lying still"),
        "held_dps": Param(0.5, "°/s", 0.05, 10.0, "held: the tremor-free rate stays within this of its window's middle"),
        "held_sigma_dps": Param(0.03, "°/s", 0.001, 1.0, "the error of a held window's mean (the hand's wander over it)"),
        "prior_dps": Param(5.0, "°/s", 0.1, 40.0, "a first estimate beyond this on an axis, not confirmed by the compass, must persist"),
        "persist_s": Param(6.0, "s", 1.0, 120.0, "how long lying still must contradict the estimate (or a large first one agree with itself) to be taken"),
        "drift_dps": Param(0.002, "°/s/√s", 0.0001, 1.0, "how fast the bias may wander (a random walk): bounds each update"),
        "ramp_dps2": Param(0.0003, "°/s²/√s", 0.0, 0.1, "how fast the bias's steady drift (a warm-up) may change; 0 = no drift rate learnt"),
        "gate_sigma": Param(4.0, "σ", 1.0, 20.0, "a window further than this from the estimate is no bias"),
    }
    #: what ``sphere bench drift --tune`` tries (every combination, on the seeds it tunes on)
    GRID = {"held_time_s": (3.0, 6.0), "drift_dps": (0.002, 0.005)}
    MAX_BIAS_DPS = 40.0  # ITG-3200 datasheet (PS-ITG-3200A-00-01.4) §3.1 Sensor Specifications: initial ZRO tolerance ±40 °/s
    ACCEL_FLOOR_G = 1.0 / 256  # one ADXL345 LSB at full resolution

    def __init__(self, still_dps: float = 3.0, still_time_s: float = 1.0, enabled: bool = True, **params):
        """``still_dps``, ``still_time_s`` and ``enabled`` are the daemon's ``[gyro]`` keys (older than this
        component: kept where users have them); ``params`` the ``[gyro_bias]`` ones (PARAMS)."""
        p = resolve(self.PARAMS, (), params)
        self.params = p
        self.still_dps = still_dps
        self.still_time_s = still_time_s
        self.held_time_s = p["held_time_s"]
        self.held_dps = p["held_dps"]
        self.enabled = enabled
        self._r_held = p["held_sigma_dps"] ** 2
        # a still window's mean: white noise of one-sided density S over T s has variance S²/(2T)
        self._r_still = ITG3200_NOISE_DPS_RT_HZ ** 2 / (2.0 * self.still_time_s)
        self._q = p["drift_dps"] ** 2  # (°/s)² per second
        self._qd = p["ramp_dps2"] ** 2  # (°/s²)² per second
        self._gate = p["gate_sigma"]
        self._prior = p["prior_dps"]
        self._persist = p["persist_s"]
        self.bias = [0.0, 0.0, 0.0]
        self.known = False
        self.variance = math.inf  # of each axis of the estimate, (°/s)²
        self.drift = [0.0, 0.0, 0.0]  # the bias's steady drift (°/s per s): a warm-up
        self._pbd = 0.0  # covariance of bias and drift, (°/s)²/s
        self._pdd = 0.0  # variance of the drift, (°/s²)²
        self.updates = 0
        self.held_updates = 0  # of them from held windows
        self.confirmed = False  # the current bias came from a window the compass confirmed
        self.rejected = 0  # still windows held back as too far from the estimate
        self.still_s = 0.0  # how long the sphere has lain still (gyro within the still band, no trend in a window)
        self._clock = 0.0
        self._last_update_s = 0.0
        self._run = None  # [sum of means, windows, seconds, confirmed]: still windows in a row that agree
        self._queued = None  # a sample left for run_deferred (add(..., defer=True))
        self._still = _Window()
        self._held = _Window() if self.held_time_s > 0 else None
        self._held_clean = True  # no lying-still window completed inside the held window (else it says the same)
        self._block = [0.0] * 11  # the held window's block: gyro integral, accel sum, field sum, their counts
        self._block_t = 0.0
        self._blocks = []

    # ------------------------------------------------------------------ samples

    def add(self, gyro_dps, accel_g_norm: float, dt_s: float, mag_uT=None, accel_g=None, defer: bool = False) -> None:
        """One sample. ``defer=True`` leaves it for :meth:`run_deferred` (so the caller can act on the sample
        first) when it cannot end a window — only a window's end changes the bias — and takes it at once when it
        may; the next add() takes a sample left behind first. The result is the same bit for bit."""
        if not self.enabled:
            return
        if self._queued is not None:
            self.run_deferred()
        held = self._held
        if defer and self._still.t + dt_s < self.still_time_s and (held is None or held.t + dt_s < self._held_len()):
            self._queued = (gyro_dps, accel_g_norm, dt_s, mag_uT, accel_g)
            return
        clock = self._clock = self._clock + dt_s
        if accel_g is not None and type(accel_g) is not tuple:
            accel_g = tuple(accel_g)
        if mag_uT is not None and type(mag_uT) is not tuple:
            mag_uT = tuple(mag_uT)
        accel_bad = abs(accel_g_norm - 1.0) > 0.15
        w = self._still
        self._take(w, gyro_dps, dt_s, accel_bad, clock, accel_g, mag_uT)
        if w.spread() > 2.0 * self.still_dps or not w.accel_ok:
            self._still = _Window()
            self.still_s = 0.0
            if self._run is not None and self._run[4] == "still":
                self._run = None  # motion breaks a run of still windows
        else:
            self.still_s += dt_s
            if w.t >= self.still_time_s:
                self._still = _Window()
                self._held_clean = False
                self._end(w, "still")
        if held is not None:
            self._held_step(held, gyro_dps, dt_s, accel_bad, clock, accel_g, mag_uT)

    def _take(self, w: _Window, g, dt_s, accel_bad, clock, accel_g, mag_uT) -> None:
        g0, g1, g2 = g  # written out (runs at every sample): the same sums and comparisons as a loop
        sm, lo, hi = w.sum, w.lo, w.hi
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
        if accel_bad:
            w.accel_ok = False
        w.n += 1
        w.t += dt_s
        if accel_g is not None:
            w.acc.add(clock, accel_g)
        if mag_uT is not None:
            w.mag.add(clock, mag_uT)

    def _held_step(self, h: _Window, g, dt_s, accel_bad, clock, accel_g, mag_uT) -> None:
        """The held window, in blocks of BLOCK_S: per sample only the block's sums; at a block's end its mean
        rate goes into the window's mean and (averaged over BLOCKS blocks: the tremor-free rate) its spread, its
        mean acceleration and field into the trends."""
        b = self._block
        b[0] += g[0] * dt_s
        b[1] += g[1] * dt_s
        b[2] += g[2] * dt_s
        if accel_g is not None:
            b[3] += accel_g[0]
            b[4] += accel_g[1]
            b[5] += accel_g[2]
            b[9] += 1
        if mag_uT is not None:
            b[6] += mag_uT[0]
            b[7] += mag_uT[1]
            b[8] += mag_uT[2]
            b[10] += 1
        if accel_bad:
            h.accel_ok = False
        self._block_t += dt_s
        h.t += dt_s
        if self._block_t < BLOCK_S:
            return
        k = 1.0 / self._block_t
        rate = (b[0] * k, b[1] * k, b[2] * k)
        if b[9]:
            h.acc.add(clock, (b[3] / b[9], b[4] / b[9], b[5] / b[9]))
        if b[10]:
            h.mag.add(clock, (b[6] / b[10], b[7] / b[10], b[8] / b[10]))
        self._block = [0.0] * 11
        self._block_t = 0.0
        sm = h.sum
        sm[0] += rate[0]
        sm[1] += rate[1]
        sm[2] += rate[2]
        h.n += 1
        blocks = self._blocks
        blocks.append(rate)
        if len(blocks) > BLOCKS:
            del blocks[0]
        if len(blocks) == BLOCKS:
            lo, hi = h.lo, h.hi
            for i in range(3):
                v = sum(bl[i] for bl in blocks) / BLOCKS
                if v < lo[i]:
                    lo[i] = v
                if v > hi[i]:
                    hi[i] = v
            if h.spread() > 2.0 * self.held_dps or not h.accel_ok:
                self._held = _Window()
                self._held_clean = True
                return
        if h.t >= self._held_len():
            self._held = _Window()
            clean, self._held_clean = self._held_clean, True
            if clean:  # lying still, the still windows said it already (and better)
                self._end(h, "held")

    def _held_len(self) -> float:
        """A held window's length: half of ``held_time_s`` until a bias is known (a first estimate sooner)."""
        return self.held_time_s if self.known else 0.5 * self.held_time_s

    def run_deferred(self) -> None:
        """The sample an ``add(..., defer=True)`` left (nothing if none)."""
        queued, self._queued = self._queued, None
        if queued is not None:
            self.add(*queued)

    # ------------------------------------------------------------------ windows

    def _end(self, w: _Window, kind: str) -> None:
        still = not w.acc.moved(self.ACCEL_FLOOR_G) and not w.mag.moved(MAG_STILL_UT)
        if kind == "still" and not still:
            self.still_s = 0.0  # a slow turn the gyro band let through
        if not still:
            self._run = None
            return
        mean = w.mean()
        if max(abs(m) for m in mean) > self.MAX_BIAS_DPS:
            self._run = None
            return
        confirmed = w.mag.n >= 0.5 * w.n
        r = self._r_still if kind == "still" else self._r_held
        if not self.known:
            if confirmed or max(abs(m) for m in mean) <= self._prior:
                self._replace(mean, r, confirmed, kind)
            else:
                self._persist_run(mean, r, w.t, confirmed, kind)
            return
        if confirmed and not self.confirmed:
            self._replace(mean, r, confirmed, kind)
            return
        # a Kalman filter per axis on (bias, its drift): predicted to now, then the window's mean
        dt = self._clock - self._last_update_s
        qd = self._qd
        pbb = self.variance + 2.0 * dt * self._pbd + dt * dt * self._pdd + self._q * dt + qd * dt ** 3 / 3.0
        pbd = self._pbd + dt * self._pdd + qd * dt * dt / 2.0
        pdd = self._pdd + qd * dt
        pred = [b + d * dt for b, d in zip(self.bias, self.drift)]
        tol = self._gate * math.sqrt(pbb + r)
        if max(abs(m - b) for m, b in zip(mean, pred)) <= tol:
            sv = pbb + r
            kb, kd = pbb / sv, pbd / sv
            self.bias = [b + kb * (m - b) for b, m in zip(pred, mean)]
            self.drift = [d + kd * (m - b) for d, b, m in zip(self.drift, pred, mean)] if qd > 0 else self.drift
            self.variance, self._pbd, self._pdd = (1.0 - kb) * pbb, (1.0 - kb) * pbd, pdd - kd * pbd
            self._updated(confirmed or self.confirmed, kind)
            return
        self.rejected += 1
        if kind == "still":
            self._persist_run(mean, r, w.t, confirmed, kind)

    def _persist_run(self, mean, r, seconds, confirmed, kind) -> None:
        """Windows that the estimate (or the prior) refuses: kept while they agree with each other; taken once
        they have lasted ``persist_s`` without a break."""
        run = self._run
        if run is not None and run[4] == kind:
            n = run[1]
            avg = [s / n for s in run[0]]
            if max(abs(m - a) for m, a in zip(mean, avg)) <= self._gate * math.sqrt(2.0 * r):
                run[0] = [s + m for s, m in zip(run[0], mean)]
                run[1] += 1
                run[2] += seconds
                run[3] = run[3] and confirmed
            else:
                run = None
        if run is None:
            run = self._run = [list(mean), 1, seconds, confirmed, kind]
        if run[2] >= self._persist:
            n = run[1]
            self._replace([s / n for s in run[0]], r / n, run[3], kind)

    def _replace(self, mean, r, confirmed, kind) -> None:
        self.bias = list(mean)
        self.variance = r
        self.drift = [0.0, 0.0, 0.0]
        self._pbd = 0.0
        self._pdd = self._qd * self._persist  # the drift is learnt again from the windows that follow
        self.known = True
        self._updated(confirmed, kind)
        self.confirmed = confirmed

    def _updated(self, confirmed, kind) -> None:
        self.updates += 1
        if kind == "held":
            self.held_updates += 1
        self.confirmed = confirmed
        self._last_update_s = self._clock
        self._run = None


class RestHold:
    """The pointer's rest hold: once the sphere has lain still for ``after_s`` (:attr:`GyroBias.still_s`: every
    gyro axis within its still band, no trend in a finished window), the pointer stays where it is as long as
    the corrected rate's mean over the last ``window_s`` stays within ±``band_dps`` on every axis and no sample
    leaves ±``still_dps`` (a slow turn of more than ``band_dps`` is never held). What it holds back is the ITG-3200's noise (its slow part, which the pointer's tightening
    lets through: about 1–2 px/s at 48 px/°) and any bias still being learnt. A move from rest leaves the band
    within a few samples (1 °/s after about 20 ms); the sample that releases the hold carries the short mean's
    whole displacement, so nothing of the move's start is lost."""

    NAME = "rest_hold"
    PARAMS = {
        "band_dps": Param(0.8, "°/s", 0.0, 5.0, "the corrected rate's short mean must stay within this to hold the pointer (0 = never hold)"),
        "window_s": Param(0.05, "s", 0.005, 1.0, "the short mean's length"),
        "after_s": Param(0.5, "s", 0.0, 30.0, "how long the sphere must have lain still before the pointer is held"),
    }

    def __init__(self, **params):
        p = resolve(self.PARAMS, (), params)
        self.band_dps = p["band_dps"]
        self.window_s = p["window_s"]
        self.after_s = p["after_s"]
        self._recent = []
        self._sum = [0.0, 0.0, 0.0]
        self._t = 0.0
        self.holding = False

    def __call__(self, rate_dps, dt_s: float, still_s: float, still_dps: float):
        """The pointer's rate for this sample: ``rate_dps`` (bias-corrected) or zeros while held."""
        recent, sm = self._recent, self._sum
        recent.append((rate_dps, dt_s))
        sm[0] += rate_dps[0] * dt_s
        sm[1] += rate_dps[1] * dt_s
        sm[2] += rate_dps[2] * dt_s
        self._t += dt_s
        while self._t - recent[0][1] >= self.window_s - 1e-9 and len(recent) > 1:
            r, d = recent.pop(0)
            sm[0] -= r[0] * d
            sm[1] -= r[1] * d
            sm[2] -= r[2] * d
            self._t -= d
        band = self.band_dps * self._t
        quiet = (self.band_dps > 0 and abs(sm[0]) <= band and abs(sm[1]) <= band and abs(sm[2]) <= band
                 and abs(rate_dps[0]) <= still_dps and abs(rate_dps[1]) <= still_dps and abs(rate_dps[2]) <= still_dps)
        if quiet and still_s >= self.after_s:
            self.holding = True
            return (0.0, 0.0, 0.0)
        if self.holding and quiet:
            # let go because a still window's trend test failed, not because the rate left the band: no move
            # began, so nothing held back is carried (the pointer's hand hold takes over from here)
            self.holding = False
            return rate_dps
        if self.holding and len(recent) > 1 and dt_s > 0:
            # released: the move began within the short mean, whose earlier samples were held back; they come
            # now, with this one (nothing of a slow aim's start is lost)
            self.holding = False
            k = 1.0 / dt_s
            return (sm[0] * k, sm[1] * k, sm[2] * k)
        self.holding = False
        return rate_dps
