"""``synthetic:hold``: a sphere held in the air by a person — the motion pointer smoothing is judged on.

It knows nothing of the filters it judges (no import from ``sphere.smoothing`` or ``sphere.daemon``).
The motion is built in physical units from a script of phases, then passed to the chip models like any
trace (:func:`sphere.sim.trace.to_chips`):

- **rest**: lying on a table — no tremor, no wander (start-up bias learning happens here);
- **held**: in the hand, aiming at nothing in particular — tremor plus slow wander;
- **turn**: a deliberate turn at a constant rate with sharp starts and stops (``ramp_s`` each), tremor
  and wander on top. Rates come from four bands: fine 1–5 °/s (aiming), slow 5–30, medium 30–90,
  fast 90–200 °/s. Turns are about the vertical (yaw: the pointer moves sideways) or about the
  horizontal axis across the pointing direction (pitch: up/down).

Hand motion, with defaults from the literature on physiological tremor:

- **Tremor**: band-limited Gaussian rotation in ``tremor_band_hz`` (8–12 Hz: the "8–12 Hz component" of
  physiological tremor, Elble & Koller, *Tremor*, Johns Hopkins 1990, ch. 2; McAuley & Marsden,
  *Brain* 123:1545–1567, 2000, §"Physiological tremor"), ``tremor_rms_deg`` = 0.1° RMS per axis (the
  angular size of a held pointing device's tremor; at 40° per 1920 px it gives 6–7 px RMS unfiltered,
  the figure the pointer issue measured). The tremor's spectrum is a raised-cosine bump over the band.
- **Wander**: low-frequency drift of a hand holding still (postural sway of the arm, below ~1 Hz;
  Riviere, Rader & Thakor, *IEEE Trans. Biomed. Eng.* 45(5):602–612, 1998, separate it from tremor at
  2 Hz): Gaussian noise low-passed below ``wander_hz`` with ``wander_rms_deg`` RMS per axis.
- **Sensors**: datasheet white noise (ITG-3200 0.38 °/s RMS, ADXL345 ~1 LSB x/y and 1.5 LSB z,
  HMC5883L 0.2 µT) and a residual gyro bias (what the device's calibration left: ``bias_dps`` drawn per
  seed within ±``bias_max_dps``), plus a slow bias drift of ``bias_drift_dps_per_min`` (temperature).

``synthetic:hold`` or ``synthetic:hold:SEED`` (an integer; each seed shuffles the turns and draws new
rates, directions, tremor and noise). :func:`hold_script` also returns the timeline for the bench.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from sphere import chips
from sphere import quaternion as quat
from sphere.sim import trace as T

RATE_HZ = 1000.0

#: Speed bands of deliberate turns, °/s (fine = aiming).
BANDS = {"fine": (1.0, 5.0), "slow": (5.0, 30.0), "medium": (30.0, 90.0), "fast": (90.0, 200.0)}


@dataclass(frozen=True)
class HoldParams:
    tremor_band_hz: tuple = (8.0, 12.0)
    tremor_rms_deg: float = 0.1
    wander_hz: float = 0.5
    wander_rms_deg: float = 0.05
    gyro_noise_dps: float = 0.38  # ITG-3200 datasheet: total RMS noise
    accel_noise_g: tuple = (1.0 / 256, 1.0 / 256, 1.5 / 256)  # ADXL345 datasheet: ~1 LSB x/y, 1.5 LSB z
    mag_noise_uT: float = 0.2  # HMC5883L datasheet: 2 mG
    bias_max_dps: float = 0.5
    bias_drift_dps_per_min: float = 0.02
    bias_dps: float | None = None  # each axis starts at ±bias_dps (the seed's signs) instead of a draw within ±bias_max_dps
    bias_ramp_dps: float = 0.0  # warm-up: each axis's bias grows by this much (away from zero) ...
    bias_ramp_s: float = 300.0  # ... linearly over these seconds from switch-on, then stays
    ramp_s: float = 0.02  # a sharp start or stop
    turn_s: float = 1.0


@dataclass(frozen=True)
class Phase:
    kind: str  # "rest", "held", "turn"
    start_s: float
    end_s: float
    band: str = ""
    rate_dps: float = 0.0  # signed: yaw positive turns left, pitch positive tips the nose down
    axis: str = ""  # "yaw" or "pitch"


@dataclass
class HoldTrace:
    motion: T.Motion
    phases: list = field(default_factory=list)
    true_gyro_dps: np.ndarray | None = None  # (N, 3) body rates without noise or bias
    quat_enu: np.ndarray | None = None  # (N, 4) the true orientation, sensor-to-ENU
    intent_quat_enu: np.ndarray | None = None  # (N, 4) the same without tremor and wander (the aim)
    bias_dps: np.ndarray | None = None  # (N, 3) the gyro's bias at every sample (°/s)


def _script(seconds: float, rng, p: HoldParams):
    """[(kind, duration, band, rate, axis)]: rest, pick up, turns of every band in a shuffled order
    with held pauses between them, put down, rest; repeated until ``seconds``."""
    turns = []
    for band, (lo, hi) in BANDS.items():
        count = 4 if band == "fine" else 2
        for k in range(count):
            rate = float(rng.uniform(lo, hi)) if band != "fine" else float(rng.choice([1.0, 2.0, 3.0, 4.0, 5.0]) if k else 3.0)
            turns.append((band, rate * (1 if rng.random() < 0.5 else -1), "yaw" if k % 2 == 0 else "pitch"))
    order = rng.permutation(len(turns))
    out = [("rest", 3.0, "", 0.0, "")]
    pitch = 0.0
    for i in order:
        band, rate, axis = turns[i]
        dur = p.turn_s if band != "fast" else p.turn_s * 0.5
        if axis == "pitch":  # keep the nose within ±45° of level (pointing, not at the ceiling)
            dur = min(dur, 45.0 / abs(rate))
            if abs(pitch + rate * dur) > 45.0:
                rate = -rate
            pitch += rate * dur
        out.append(("held", float(rng.uniform(1.5, 2.5)), "", 0.0, ""))
        out.append(("turn", dur, band, rate, axis))
    out += [("held", 2.0, "", 0.0, ""), ("rest", 3.0, "", 0.0, "")]
    total = sum(d for _, d, *_ in out)
    while total < seconds:
        out.append(("rest", seconds - total, "", 0.0, ""))
        total = seconds
    return out


def _band_noise(rng, n: int, rate_hz: float, lo_hz: float, hi_hz: float, rms: float) -> np.ndarray:
    """Gaussian noise with a raised-cosine spectrum over [lo_hz, hi_hz], scaled to ``rms``."""
    spec = np.fft.rfft(rng.normal(0.0, 1.0, n))
    f = np.fft.rfftfreq(n, 1.0 / rate_hz)
    mid, half = 0.5 * (lo_hz + hi_hz), 0.5 * (hi_hz - lo_hz)
    shape = np.where(np.abs(f - mid) <= half, 0.5 * (1.0 + np.cos(np.pi * (f - mid) / half)), 0.0)
    x = np.fft.irfft(spec * shape, n)
    s = x.std()
    return x * (rms / s) if s > 0 else x


def _low_noise(rng, n: int, rate_hz: float, corner_hz: float, rms: float) -> np.ndarray:
    spec = np.fft.rfft(rng.normal(0.0, 1.0, n))
    f = np.fft.rfftfreq(n, 1.0 / rate_hz)
    x = np.fft.irfft(spec / (1.0 + (f / corner_hz) ** 2), n)
    s = x.std()
    return x * (rms / s) if s > 0 else x


def _smooth_rate(profile: np.ndarray, rate_hz: float, ramp_s: float) -> np.ndarray:
    """Starts and stops of a rate profile made linear over ``ramp_s`` (a moving mean), travel kept."""
    k = max(1, int(round(ramp_s * rate_hz)))
    return np.convolve(profile, np.ones(k) / k, mode="full")[: len(profile)]


def hold_script(seconds: float = 60.0, seed: int = 0, params: HoldParams | None = None,
                rate_hz: float = RATE_HZ, script=None) -> HoldTrace:
    """The motion and its timeline; ``script`` = [(kind, seconds, band, rate_dps, axis)] instead of the seed's
    shuffled one (e.g. ``[("rest", 3, "", 0, ""), ("held", 5, "", 0, ""), ("turn", 1, "fine", 3, "yaw")]``)."""
    p = params or HoldParams()
    rng = np.random.default_rng(seed)
    script = _script(seconds, rng, p) if script is None else list(script)
    n = int(round(seconds * rate_hz))
    yaw_rate = np.zeros(n)
    pitch_rate = np.zeros(n)
    in_hand = np.zeros(n)
    phases, t = [], 0.0
    for kind, dur, band, rate, axis in script:
        a, b = int(round(t * rate_hz)), min(n, int(round((t + dur) * rate_hz)))
        if a >= n:
            break
        if kind == "turn":
            (yaw_rate if axis == "yaw" else pitch_rate)[a:b] = rate
        if kind != "rest":
            in_hand[a:b] = 1.0
        phases.append(Phase(kind, a / rate_hz, b / rate_hz, band, rate, axis))
        t += dur
    yaw_rate = _smooth_rate(yaw_rate, rate_hz, p.ramp_s)
    pitch_rate = _smooth_rate(pitch_rate, rate_hz, p.ramp_s)
    # picking up and putting down fade the hand's motion in over 0.2 s
    hand = _smooth_rate(in_hand, rate_hz, 0.2)
    tremor = np.stack([_band_noise(rng, n, rate_hz, *p.tremor_band_hz, p.tremor_rms_deg) for _ in range(3)], axis=1)
    wander = np.stack([_low_noise(rng, n, rate_hz, p.wander_hz, p.wander_rms_deg) for _ in range(3)], axis=1)
    small = np.radians((tremor + wander) * hand[:, None])  # body-frame rotation vector of the hand's motion
    yaw = np.radians(np.cumsum(yaw_rate) / rate_hz)
    pitch = np.radians(np.cumsum(pitch_rate) / rate_hz)
    ez, ey = np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])
    q_aim = quat.multiply(quat.from_axis_angle(ez, yaw), quat.from_axis_angle(ey, pitch))
    ang = np.linalg.norm(small, axis=1)
    axis = np.where(ang[:, None] > 1e-15, small / np.maximum(ang, 1e-15)[:, None], ez)
    q = quat.normalize(quat.multiply(q_aim, quat.from_axis_angle(axis, ang)))
    true_gyro = np.degrees(T._body_rates(q, rate_hz))
    ideal = T._from_orientation(q, np.radians(true_gyro), rate_hz, "hold")
    bias = rng.uniform(-p.bias_max_dps, p.bias_max_dps, 3)
    drift = p.bias_drift_dps_per_min / 60.0 * np.arange(n)[:, None] / rate_hz * rng.choice([-1.0, 1.0], 3)
    if p.bias_dps is not None or p.bias_ramp_dps:
        # a fixed start and a warm-up ramp (the ITG-3200's zero-rate output moves with its die temperature,
        # datasheet §3.1 "ZRO variation over temperature"): drawn after the rest, so the seed's motion stays
        sign = np.sign(bias) if p.bias_dps is None else rng.choice([-1.0, 1.0], 3)
        bias = bias if p.bias_dps is None else p.bias_dps * sign
        ramp = np.minimum(np.arange(n) / rate_hz / p.bias_ramp_s, 1.0)
        drift = drift + p.bias_ramp_dps * ramp[:, None] * sign
    gyro = true_gyro + bias + drift + rng.normal(0.0, p.gyro_noise_dps, (n, 3))
    g = chips.STANDARD_GRAVITY_M_S2
    acc = ideal.acc_m_s2 + rng.normal(0.0, 1.0, (n, 3)) * np.asarray(p.accel_noise_g) * g
    mag = ideal.mag_uT + rng.normal(0.0, p.mag_noise_uT, (n, 3))
    motion = T.Motion(rate_hz, acc, np.radians(gyro), mag, f"hold_{seed}")
    return HoldTrace(motion, phases, true_gyro, q, q_aim, bias + drift)


def _band(rate_dps: float) -> str:
    return next(b for b, (lo, hi) in BANDS.items() if abs(rate_dps) <= hi or b == "fast")


def startup_turn_script(rate_dps: float = 20.0, turn_s: float = 3.0, still_s: float = 11.0) -> list:
    """A steady turn about the vertical from switch-on (the first sample), then laid still: the case in which
    nothing but a later stop tells the turn from a gyro bias when the magnetometer does not answer. Run it with
    :data:`CLEAN` (a turntable's motion: no tremor, no wander)."""
    return [("turn", turn_s, _band(rate_dps), rate_dps, "yaw"), ("rest", still_s, "", 0.0, "")]


def long_hold_script(seconds: float = 600.0, seed: int = 0, aim_every_s: float = 20.0) -> list:
    """Switched on in the hand and never laid down: held still, with an aim (a fine or slow turn of 0.5–1.5 s,
    yaw or pitch, each undoing about half the last aim's offset so the aim stays near the screen's middle)
    every ``aim_every_s`` (± 15 %)."""
    rng = np.random.default_rng(10_000 + seed)
    out, t, k = [], 0.0, 0
    aim = {"yaw": 0.0, "pitch": 0.0}
    while t < seconds:
        held = float(rng.uniform(0.85, 1.15) * aim_every_s)
        out.append(("held", min(held, seconds - t), "", 0.0, ""))
        t += held
        if t >= seconds:
            break
        band = "fine" if k % 2 == 0 else "slow"
        axis = "yaw" if rng.random() < 0.6 else "pitch"
        lo, hi = BANDS[band]
        rate = float(rng.uniform(lo, min(hi, 15.0)))
        dur = float(rng.uniform(0.5, 1.5))
        if aim[axis] > 0 or (aim[axis] == 0 and rng.random() < 0.5):
            rate = -rate
        aim[axis] += rate * dur
        out.append(("turn", min(dur, seconds - t), band, rate, axis))
        t += dur
        k += 1
    return out


def stops_script(seed: int = 0, held_s: tuple = (1.5, 2.5)) -> list:
    """Picked up from the table, then turns in every band with hard stops (three each, fast ones of 0.15–0.4 s;
    yaw and pitch; each turn's direction brings the aim back towards its start), held between them, put down."""
    rng = np.random.default_rng(20_000 + seed)
    turns = [(band, k) for band in BANDS for k in range(3)]
    out = [("rest", 3.0, "", 0.0, "")]
    aim = {"yaw": 0.0, "pitch": 0.0}
    for i in rng.permutation(len(turns)):
        band, k = turns[i]
        lo, hi = BANDS[band]
        rate = float(rng.uniform(lo, hi))
        axis = "yaw" if k != 1 else "pitch"
        dur = float(rng.uniform(0.15, 0.4)) if band == "fast" else float(rng.uniform(0.5, 1.0))
        if axis == "pitch":
            dur = min(dur, 30.0 / rate)
        if aim[axis] > 0 or (aim[axis] == 0 and rng.random() < 0.5):
            rate = -rate
        aim[axis] += rate * dur
        out.append(("held", float(rng.uniform(*held_s)), "", 0.0, ""))
        out.append(("turn", dur, band, rate, axis))
    out += [("held", 2.0, "", 0.0, ""), ("rest", 3.0, "", 0.0, "")]
    return out


def script_seconds(script) -> float:
    return float(sum(step[1] for step in script))


def synthetic(seconds: float, arg: str = "") -> T.Motion:
    """The registry entry of ``synthetic:hold[:SEED]``."""
    try:
        seed = int(arg) if arg else 0
    except ValueError:
        raise ValueError(f"the seed must be an integer, not {arg!r}") from None
    return hold_script(seconds, seed).motion


def with_params(**changes) -> HoldParams:
    return replace(HoldParams(), **changes)


#: a turntable's motion: the sphere turned without a hand (no tremor, no wander)
CLEAN = HoldParams(tremor_rms_deg=0.0, wander_rms_deg=0.0)
#: a warm-up: each axis's bias starts at ±0.6 °/s and grows by a further 0.5 °/s over 5 minutes (and no other drift)
WARM_UP = HoldParams(bias_dps=0.6, bias_ramp_dps=0.5, bias_ramp_s=300.0, bias_drift_dps_per_min=0.0)
#: hard stops: starts and stops within 10 ms
HARD_STOPS = HoldParams(ramp_s=0.01)
