"""Motion traces for the simulated board.

A trace is what the three chip models output: for each chip, samples in the chip's own units at the
chip's output data rate, rounded and saturated as the chip does (:mod:`sphere.chips`):

- ADXL345 full resolution, 256 LSB/g, ±16 g (13 bits), at 200 Hz;
- ITG-3200, 14.375 LSB/(°/s), at 200 Hz (SMPLRT_DIV = 4 with the 1 kHz internal rate);
- HMC5883L gain 1, 1090 LSB/gauss, −4096 on an overflowing axis, at 75 Hz.

Sources in physical units (m/s², rad/s, µT in the sensor frame, as BROAD stores them) are resampled to
each chip's rate by linear interpolation. The board's models hold each sample for one period of the rate
the firmware configures, so a trace at another rate still plays at the right speed.

File format (little-endian), read by hardware/sim/sensors.c::

    b"SPHTRACE", u32 version = 1,
    then for accel, gyro, mag: f64 rate_hz, u32 count, count × 3 × i16 (x, y, z)
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sphere import chips
from sphere import quaternion as quat
from sphere.protocol import RawSample
from sphere.protocol.packets import RAW_ACCEL_OK, RAW_GYRO_OK, RAW_MAG_FRESH, RAW_MAG_OK
from sphere.settings import load

ACCEL_RATE_HZ = 200.0
GYRO_RATE_HZ = 200.0
MAG_RATE_HZ = 75.0
MAGIC = b"SPHTRACE"
VERSION = 1

#: Earth's field used by the synthetic sources, ENU µT: 20 µT north, 45 µT down (Berlin-like).
EARTH_FIELD_ENU_UT = np.array([0.0, 20.0, -45.0])
GRAVITY_UP_M_S2 = np.array([0.0, 0.0, chips.STANDARD_GRAVITY_M_S2])


@dataclass
class Motion:
    """Motion in physical units on a common time base (sensor frame)."""

    rate_hz: float
    acc_m_s2: np.ndarray  # (N, 3)
    gyr_rad_s: np.ndarray  # (N, 3)
    mag_uT: np.ndarray  # (N, 3)
    name: str = "motion"

    @property
    def seconds(self) -> float:
        return len(self.acc_m_s2) / self.rate_hz


@dataclass
class ChipTrace:
    """Chip units at the chips' rates: what the board's sensor models output."""

    accel_lsb: np.ndarray
    gyro_lsb: np.ndarray
    mag_lsb: np.ndarray
    accel_rate_hz: float = ACCEL_RATE_HZ
    gyro_rate_hz: float = GYRO_RATE_HZ
    mag_rate_hz: float = MAG_RATE_HZ

    @property
    def seconds(self) -> float:
        return len(self.accel_lsb) / self.accel_rate_hz

    def write(self, path: Path | str) -> Path:
        path = Path(path)
        with open(path, "wb") as f:
            f.write(MAGIC + struct.pack("<I", VERSION))
            for data, rate in ((self.accel_lsb, self.accel_rate_hz), (self.gyro_lsb, self.gyro_rate_hz),
                               (self.mag_lsb, self.mag_rate_hz)):
                a = np.ascontiguousarray(data, dtype="<i2").reshape(-1, 3)
                f.write(struct.pack("<dI", float(rate), len(a)))
                f.write(a.tobytes())
        return path

    @staticmethod
    def read(path: Path | str) -> "ChipTrace":
        raw = Path(path).read_bytes()
        if raw[:8] != MAGIC or struct.unpack_from("<I", raw, 8)[0] != VERSION:
            raise ValueError(f"{path} is not a sphere trace (version {VERSION})")
        off = 12
        parts = []
        for _ in range(3):
            rate, n = struct.unpack_from("<dI", raw, off)
            off += 12
            a = np.frombuffer(raw, dtype="<i2", count=3 * n, offset=off).reshape(n, 3).astype(np.int16)
            off += 6 * n
            parts.append((a, rate))
        return ChipTrace(parts[0][0], parts[1][0], parts[2][0], parts[0][1], parts[1][1], parts[2][1])


def resample(x: np.ndarray, rate_in: float, rate_out: float) -> np.ndarray:
    """Linear interpolation of (N, 3) samples at rate_in onto rate_out, over the same duration."""
    x = np.asarray(x, dtype=float)
    n_out = int(np.floor(len(x) * rate_out / rate_in))
    t_in = np.arange(len(x)) / rate_in
    t_out = np.arange(n_out) / rate_out
    return np.stack([np.interp(t_out, t_in, x[:, i]) for i in range(3)], axis=1)


def fill_gaps(x: np.ndarray) -> np.ndarray:
    """Replace non-finite samples by the previous finite one (the first finite one at the start)."""
    x = np.array(x, dtype=float)
    ok = np.all(np.isfinite(x), axis=1)
    if not ok.any():
        return np.zeros_like(x)
    idx = np.where(ok, np.arange(len(x)), 0)
    np.maximum.accumulate(idx, out=idx)
    first = int(np.argmax(ok))
    idx[:first] = first
    return x[idx]


def to_chips(m: Motion, accel_rate_hz=ACCEL_RATE_HZ, gyro_rate_hz=GYRO_RATE_HZ, mag_rate_hz=MAG_RATE_HZ) -> ChipTrace:
    """Resample a motion to the chips' rates and convert it to chip units (quantised, saturated)."""
    return ChipTrace(
        chips.accel_m_s2_to_lsb(resample(fill_gaps(m.acc_m_s2), m.rate_hz, accel_rate_hz)),
        chips.gyro_rad_s_to_lsb(resample(fill_gaps(m.gyr_rad_s), m.rate_hz, gyro_rate_hz)),
        chips.mag_uT_to_lsb(resample(fill_gaps(m.mag_uT), m.rate_hz, mag_rate_hz)),
        accel_rate_hz, gyro_rate_hz, mag_rate_hz,
    )


def hold_first(m: Motion, seconds: float) -> Motion:
    """Prepend ``seconds`` of the first sample with zero rotation (the sphere lying still at power-up)."""
    n = int(round(seconds * m.rate_hz))
    if n <= 0:
        return m
    def rep(x, zero=False):
        first = np.zeros(3) if zero else fill_gaps(x)[0]
        return np.concatenate([np.tile(first, (n, 1)), x])
    return Motion(m.rate_hz, rep(m.acc_m_s2), rep(m.gyr_rad_s, zero=True), rep(m.mag_uT), m.name)


def from_broad(trial, start_s: float = 0.0, seconds: float | None = None) -> Motion:
    """A BROAD trial (sphere.broad.Trial) or a slice of it, as a motion."""
    if start_s or seconds is not None:
        trial = trial.seconds(start_s, seconds if seconds is not None else len(trial) / trial.rate_hz - start_s)
    return Motion(trial.rate_hz, trial.acc_m_s2, trial.gyr_rad_s, trial.mag_uT, trial.name)


# ---------------------------------------------------------------- synthetic sources

SYNTH_RATE_HZ = 1000.0


def _from_orientation(q_enu: np.ndarray, gyr_rad_s: np.ndarray, rate_hz: float, name: str,
                      free_fall: np.ndarray | None = None, extra_acc: np.ndarray | None = None) -> Motion:
    """Sensor readings for a sensor-to-ENU orientation history: gravity and the field rotated in."""
    qc = quat.conjugate(q_enu)
    acc = quat.rotate(qc, np.broadcast_to(GRAVITY_UP_M_S2, (len(q_enu), 3)))
    if free_fall is not None:
        acc[free_fall] = 0.0
    if extra_acc is not None:
        acc = acc + extra_acc
    mag = quat.rotate(qc, np.broadcast_to(EARTH_FIELD_ENU_UT, (len(q_enu), 3)))
    return Motion(rate_hz, acc, gyr_rad_s, mag, name)


def _integrate(gyr_rad_s: np.ndarray, rate_hz: float, q0=(1.0, 0.0, 0.0, 0.0)) -> np.ndarray:
    """Orientation before each sample: q[i] = q0 ⊗ Δq_0 ⊗ … ⊗ Δq_(i-1), Δq_k the turn of sample k's rate over
    1/rate_hz. The running product is a prefix scan (log2 N batched products, Hillis–Steele), not a loop
    per sample: 600 s at 1 kHz in well under a second instead of 40 s (the wait before --simulate starts)."""
    w = np.asarray(gyr_rad_s, dtype=float)
    n = len(w)
    q = np.empty((n, 4))
    if n == 0:
        return q
    angle = np.linalg.norm(w, axis=1)
    half = angle / (2.0 * rate_hz)
    scale = np.divide(np.sin(half), angle, out=np.zeros_like(angle), where=angle > 0)
    step = np.concatenate([np.cos(half)[:, None], w * scale[:, None]], axis=1)  # Δq_k
    prefix = np.concatenate([np.asarray(q0, dtype=float)[None, :], step[:-1]])  # q0, Δq_0 … Δq_(n-2)
    k = 1
    while k < n:  # prefix[i] ← prefix[i-k] ⊗ prefix[i]: after the pass, each holds the product of 2k terms
        a, b = prefix[:-k].T, prefix[k:].T
        prefix[k:] = np.column_stack(quat.mul(a, b))  # on the columns: no per-pass moveaxis/stack copies
        k *= 2
    q[:] = quat.normalize(prefix)
    return q


def still(seconds: float, rate_hz: float = SYNTH_RATE_HZ) -> Motion:
    n = int(round(seconds * rate_hz))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return _from_orientation(q, np.zeros((n, 3)), rate_hz, "still")


def rotation(seconds: float, rate_dps: float = 90.0, axis=(0.0, 0.0, 1.0), still_s: float = 1.0,
             rate_hz: float = SYNTH_RATE_HZ) -> Motion:
    """Still for ``still_s``, then constant rotation at ``rate_dps`` about a sensor-frame axis."""
    n = int(round(seconds * rate_hz))
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    gyr = np.zeros((n, 3))
    gyr[int(round(still_s * rate_hz)):] = np.radians(rate_dps) * a
    return _from_orientation(_integrate(gyr, rate_hz), gyr, rate_hz, f"rotation_{rate_dps:g}dps")


def sway(seconds: float, peak_dps: float = 150.0, period_s: float = 1.3, axis=(0.0, 0.0, 1.0), still_s: float = 1.0,
         rate_hz: float = SYNTH_RATE_HZ) -> Motion:
    """Still for ``still_s``, then turning back and forth about a sensor-frame axis, the rate
    ``peak_dps``·sin(2π t / ``period_s``): never still for a whole second, never a steady turn."""
    n = int(round(seconds * rate_hz))
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    i0 = int(round(still_s * rate_hz))
    gyr = np.zeros((n, 3))
    t = np.arange(n - i0) / rate_hz
    gyr[i0:] = np.radians(peak_dps) * np.sin(2 * np.pi * t / period_s)[:, None] * a
    return _from_orientation(_integrate(gyr, rate_hz), gyr, rate_hz, f"sway_{peak_dps:g}dps")


def toss(seconds: float = 4.0, toss_at_s: float = 2.0, flight_s: float = 0.4, spin_dps: float = 200.0,
         rate_hz: float = SYNTH_RATE_HZ) -> Motion:
    """Still, a throw (1.5 g up for 0.1 s), free flight (0 g, spinning), a catch (3 g for 0.05 s), still."""
    n = int(round(seconds * rate_hz))
    t = np.arange(n) / rate_hz
    throw = (t >= toss_at_s - 0.1) & (t < toss_at_s)
    flight = (t >= toss_at_s) & (t < toss_at_s + flight_s)
    catch = (t >= toss_at_s + flight_s) & (t < toss_at_s + flight_s + 0.05)
    gyr = np.zeros((n, 3))
    gyr[flight] = np.radians([spin_dps, 0.0, 0.0])
    q = _integrate(gyr, rate_hz)
    extra = np.zeros((n, 3))
    qc = quat.conjugate(q)
    extra[throw] = quat.rotate(qc[throw], np.broadcast_to(0.5 * GRAVITY_UP_M_S2, (throw.sum(), 3)))
    extra[catch] = quat.rotate(qc[catch], np.broadcast_to(2.0 * GRAVITY_UP_M_S2, (catch.sum(), 3)))
    return _from_orientation(q, gyr, rate_hz, "toss", free_fall=flight, extra_acc=extra)


def taps(seconds: float = 4.0, at_s=(1.0, 2.0, 2.15), peak_g: float = 4.0, width_s: float = 0.012,
         axis: int = 2, rate_hz: float = SYNTH_RATE_HZ) -> Motion:
    """Still, with short half-sine acceleration spikes (taps on the shell) at the given times."""
    m = still(seconds, rate_hz)
    t = np.arange(len(m.acc_m_s2)) / rate_hz
    acc = m.acc_m_s2.copy()
    for t0 in at_s:
        s = (t >= t0) & (t < t0 + width_s)
        acc[s, axis] += peak_g * chips.STANDARD_GRAVITY_M_S2 * np.sin(np.pi * (t[s] - t0) / width_s)
    return Motion(rate_hz, acc, m.gyr_rad_s, m.mag_uT, "taps")


# ---------------------------------------------------------------- a sphere that needs calibrating

#: The imperfections of ``synthetic:calibration``, in physical units, applied before the chip conversion
#: (tests compare what `sphere calibrate` recovers with them):
#:   gyro reading  = true + CAL_GYRO_BIAS_DPS                       (°/s)
#:   accel reading = CAL_ACCEL_SCALE · true + CAL_ACCEL_OFFSET_G    (g, per axis)
#:   mag reading   = CAL_MAG_SOFT_IRON · true + CAL_MAG_HARD_IRON_UT (µT)
CAL_GYRO_BIAS_DPS = np.array([1.8, -2.6, 0.9])
CAL_ACCEL_OFFSET_G = np.array([0.035, -0.025, 0.050])
CAL_ACCEL_SCALE = np.array([1.030, 0.970, 1.015])
CAL_MAG_HARD_IRON_UT = np.array([12.0, -8.0, 15.0])
CAL_MAG_SOFT_IRON = np.array([[1.06, 0.03, -0.02], [0.03, 0.95, 0.04], [-0.02, 0.04, 1.01]])
#: White noise (RMS per axis) like the chips' datasheets: ITG-3200 0.38 °/s, ADXL345 about 1 LSB
#: (3.9 mg) on x, y and 1.5 LSB on z, HMC5883L 2 mG (0.2 µT).
CAL_NOISE_GYRO_DPS = 0.38
CAL_NOISE_ACCEL_G = np.array([1.0, 1.0, 1.5]) / chips.ADXL345_LSB_PER_G
CAL_NOISE_MAG_UT = 0.2
CAL_SEED = 20261122

#: The script: still (z up), then turned back and forth about each body axis in turn (x, y, z: a quarter
#: turn each way, as the axis check of `sphere calibrate` asks), then each face up in turn (a smooth
#: rotation, then held still), then slow tumbling through every direction for CAL_TUMBLE_S, back to z up,
#: and again from the start, so `sphere calibrate` started at any time finds every pose it asks for within
#: one round. Each hold is longer than the calibration's 3 s still (sphere.calibration.session.STILL_S),
#: with room for its 0.25 s stillness blocks, so a session that joins after the first still phase can use
#: a face's hold.
CAL_STILL_S = 5.0
CAL_SWING_DEG = 90.0  # each axis: 0 → +90° → 0 → −90° → 0 ...
CAL_SWING_S = 0.9  # ... each quarter turn in this long (smoothstep: at most about 150 °/s)
CAL_MOVE_S = 1.0
CAL_HOLD_S = 3.5
CAL_TUMBLE_S = 30.0
CAL_TUMBLE_DPS = (30.0, 90.0, 120.0)  # nested rotations about the earth's z, y and x axes (°/s)


def _face_orientations() -> list[tuple[str, np.ndarray]]:
    """Sensor-to-ENU orientations with each axis up in turn (a different heading each), ending z up."""
    x, y, z = np.eye(3)
    faces = [("+x", quat.from_axis_angle(y, -np.pi / 2)), ("+y", quat.from_axis_angle(x, np.pi / 2)),
             ("-x", quat.from_axis_angle(y, np.pi / 2)), ("-y", quat.from_axis_angle(x, -np.pi / 2)),
             ("-z", quat.from_axis_angle(x, np.pi)), ("+z", np.array([1.0, 0.0, 0.0, 0.0]))]
    return [(name, quat.multiply(quat.from_axis_angle(z, np.radians(50.0 * i)), q)) for i, (name, q) in enumerate(faces)]


def _slerp(p: np.ndarray, q: np.ndarray, u: np.ndarray) -> np.ndarray:
    d = float(np.dot(p, q))
    if d < 0:
        q, d = -q, -d
    th = np.arccos(min(d, 1.0))
    if th < 1e-9:
        return np.tile(p, (len(u), 1))
    u = u[:, None]
    return (np.sin((1 - u) * th) * p + np.sin(u * th) * q) / np.sin(th)


def _body_rates(q: np.ndarray, rate_hz: float) -> np.ndarray:
    """Sensor-frame angular velocity (rad/s) of a sensor-to-earth orientation history."""
    dq = quat.multiply(quat.conjugate(q[:-1]), q[1:])
    dq *= np.where(dq[:, :1] < 0, -1.0, 1.0)
    s = np.linalg.norm(dq[:, 1:], axis=1)
    ang = 2.0 * np.arctan2(s, dq[:, 0])
    w = np.where(s[:, None] > 1e-12, dq[:, 1:] / np.maximum(s, 1e-12)[:, None] * ang[:, None], 0.0) * rate_hz
    return np.vstack([w, w[-1:]]) if len(w) else np.zeros((len(q), 3))


def calibration_script(seconds: float, rate_hz: float = SYNTH_RATE_HZ):
    """The orientation history of ``synthetic:calibration`` (sensor-to-ENU) and its timeline
    [(name, start_s, end_s)]: "still", the swings about each axis ("turn x" …), each face's hold ("+x" …),
    "tumble"."""
    n = int(round(seconds * rate_hz))
    qs, timeline = [], []
    upright = np.array([1.0, 0.0, 0.0, 0.0])
    cur = upright
    t = 0.0
    have = 0  # samples so far

    def add(q, name=None):
        nonlocal t, have
        if name is not None:
            timeline.append((name, t, t + len(q) / rate_hz))
        qs.append(q)
        t += len(q) / rate_hz
        have += len(q)

    def move_to(q):
        move = CAL_MOVE_S * (1.5 if float(abs(np.dot(cur, q))) < 0.5 else 1.0)  # 180° turns take longer
        u = np.arange(int(round(move * rate_hz))) / (move * rate_hz)
        add(_slerp(cur, q, u * u * (3 - 2 * u)))  # smoothstep: starts and stops gently

    def swings(axis):
        m = int(round(CAL_SWING_S * rate_hz))
        u = np.arange(m) / m
        u = u * u * (3 - 2 * u)
        a = np.radians(CAL_SWING_DEG)
        angle = np.concatenate([a * u, a * (1 - u), -a * u, -a * (1 - u)])
        return quat.multiply(cur, quat.from_axis_angle(axis, angle))  # about the sensor's own axis

    while have < n:
        if have:  # a new round: back to z up
            move_to(upright)
            cur = upright
        add(np.tile(cur, (int(round(CAL_STILL_S * rate_hz)), 1)), "still")
        for k, axis in enumerate(np.eye(3)):
            add(swings(axis), "turn " + "xyz"[k])
        for name, q in _face_orientations():
            move_to(q)
            add(np.tile(q, (int(round(CAL_HOLD_S * rate_hz)), 1)), name)
            cur = q
        m = int(round(CAL_TUMBLE_S * rate_hz))
        tt = np.arange(m) / rate_hz
        ramp = np.where(tt < 0.5, tt * tt, tt - 0.25)  # the rates ramp up over 0.5 s
        rz, ry, rx = (np.radians(r) * ramp for r in CAL_TUMBLE_DPS)
        ez, ey, ex = np.eye(3)[2], np.eye(3)[1], np.eye(3)[0]
        tumble = quat.multiply(quat.multiply(quat.multiply(quat.from_axis_angle(ez, rz), quat.from_axis_angle(ey, ry)),
                                             quat.from_axis_angle(ex, rx)), cur)
        add(tumble, "tumble")
        cur = tumble[-1]
    timeline = [(name, t0, min(t1, n / rate_hz)) for name, t0, t1 in timeline if t0 < n / rate_hz]
    return np.vstack(qs)[:n], timeline


def calibration(seconds: float = 45.0, rate_hz: float = SYNTH_RATE_HZ, seed: int = CAL_SEED) -> Motion:
    """A sphere that needs calibrating, turned as `sphere calibrate` asks: still, about each axis, six faces, tumbling —
    with the CAL_* imperfections and chip-like noise applied in physical units."""
    q, _ = calibration_script(seconds, rate_hz)
    n = len(q)
    rng = np.random.default_rng(seed)
    ideal = _from_orientation(q, _body_rates(q, rate_hz), rate_hz, "calibration")
    g = chips.STANDARD_GRAVITY_M_S2
    acc = (ideal.acc_m_s2 * CAL_ACCEL_SCALE + CAL_ACCEL_OFFSET_G * g
           + rng.normal(0.0, 1.0, (n, 3)) * CAL_NOISE_ACCEL_G * g)
    gyr = ideal.gyr_rad_s + np.radians(CAL_GYRO_BIAS_DPS + rng.normal(0.0, CAL_NOISE_GYRO_DPS, (n, 3)))
    mag = ideal.mag_uT @ CAL_MAG_SOFT_IRON.T + CAL_MAG_HARD_IRON_UT + rng.normal(0.0, CAL_NOISE_MAG_UT, (n, 3))
    return Motion(rate_hz, acc, gyr, mag, "calibration")


#: synthetic:rotation's limit either way, in °/s: the ITG-3200 reads up to ±2000 (its full scale), so a faster
#: turn only saturates it; a rate past this (1e99, nan) is a typo, not a motion
MAX_ROTATION_DPS = 10000.0


def _rotation(seconds: float, arg: str) -> Motion:
    """``synthetic:rotation[:DPS]``."""
    try:
        dps = float(arg) if arg else 90.0
    except ValueError:
        raise ValueError(f"the rate must be a number of degrees a second, not {arg!r}") from None
    if not abs(dps) <= MAX_ROTATION_DPS:  # (nan fails too)
        raise ValueError(f"the rate must be a number of degrees a second up to {MAX_ROTATION_DPS:g} either way "
                         f"(the ITG-3200 reads up to 2000), not {arg}")
    return rotation(seconds, rate_dps=dps)


def _no_arg(fn):
    """A source that takes no ``:ARG``: one given is refused, not ignored."""

    def entry(seconds: float, arg: str) -> Motion:
        if arg:
            raise ValueError("takes no argument")
        return fn(seconds)

    return entry


#: The synthetic sources: NAME -> a function ``(seconds: float, arg: str) -> Motion`` (``arg`` is the text
#: after ``synthetic:NAME:``, "" when none), or the same as a lazily imported ``"module:function"`` string
#: (so a source in its own module under sphere/sim may import this one). A new source = its module + one line.
SYNTHETIC = {
    "still": _no_arg(still),
    "rotation": _rotation,
    "toss": _no_arg(lambda seconds: toss(seconds, toss_at_s=min(2.0, seconds / 2))),
    "taps": _no_arg(taps),
    "calibration": _no_arg(calibration),
    "hold": "sphere.sim.hold:synthetic",
    "onsets": "sphere.sim.onsets:synthetic",
    "tour": "sphere.sim.tour:synthetic",
    "turn": "sphere.sim.turn:synthetic",
}


def synthetic(spec: str, seconds: float) -> Motion:
    """``NAME[:ARG]`` from :data:`SYNTHETIC` for ``seconds``."""
    name, _, arg = spec.partition(":")
    if name not in SYNTHETIC:
        raise ValueError(f"unknown synthetic source {name!r}; one of {', '.join(SYNTHETIC)}")
    fn = SYNTHETIC[name]
    if isinstance(fn, str):
        fn = load(fn)
    try:
        return fn(seconds, arg)
    except ValueError as e:
        raise ValueError(f"synthetic:{spec}: {e}") from None


def raw_packets(motion) -> list:
    """(t_us, RawSample) at the gyro's rate from a motion, through the chip models' units and rates (device time
    from 1 s), as the firmware would send them."""
    ct = to_chips(motion)
    n = min(len(ct.accel_lsb), len(ct.gyro_lsb))
    last_mag = -1
    out = []
    for i in range(n):
        t = i / ct.gyro_rate_hz
        m = min(int(t * ct.mag_rate_hz), len(ct.mag_lsb) - 1)
        flags = RAW_ACCEL_OK | RAW_GYRO_OK | RAW_MAG_OK | (RAW_MAG_FRESH if m != last_mag else 0)
        last_mag = m
        t_us = int(round(1_000_000 + t * 1e6))
        out.append((t_us, RawSample(t_us=t_us & 0xFFFFFFFF, flags=flags, accel=tuple(int(v) for v in ct.accel_lsb[i]),
                                    gyro=tuple(int(v) for v in ct.gyro_lsb[i]), mag=tuple(int(v) for v in ct.mag_lsb[m]))))
    return out
