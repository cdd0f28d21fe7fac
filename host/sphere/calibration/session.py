"""What the guided calibration waits for, judged from the RAW_SAMPLE stream: pure functions on arrays in
chip units (LSB) and **device** time (seconds from RAW_SAMPLE ``t_us``), so the result does not depend
on how fast the link or the simulated board runs. ``sphere calibrate`` does the I/O and the printing.

- :func:`still_spans` — where the sphere lay still. Device time is cut into blocks of ``BLOCK_S``; a
  block is *quiet* when every axis' standard deviation stays within the chips' noise (:class:`Stillness`),
  and a span is a run of quiet blocks whose means stay within a small drift of the span's first block
  (a slow steady turn has a steady gyro, but the accelerometer or the field then drifts).
- :func:`trailing_still` — the still span reaching the newest complete block: "still for how long now".
- :func:`classify_face` — which axis points up (±x, ±y, ±z) from a still span's mean acceleration.
- :func:`update_faces` — the six-position step: faces seen so far, a face seen again replaced by the newer.
- :func:`field_coverage` — how much of the sphere of field directions the magnetometer has seen: the
  fraction of ``COVERAGE_BINS`` nearly equal-area direction bins (a Fibonacci lattice) that hold a
  reading, directions taken from a centre fitted to the cloud (a sphere fit, so hard iron does not skew them).
- :func:`turn_status` — the magnetometer step: done at ``COVERAGE_TARGET`` after ``TURN_MIN_S``, or at ``TURN_S``.
- :func:`from_series` — everything from one recording (``sphere calibrate --capture``), with the same detection.
"""

from __future__ import annotations

import bisect
import functools
from dataclasses import dataclass, field

import numpy as np

from sphere import chips
from sphere.calibration import fit as calibration
from sphere.protocol import PacketStream
from sphere.protocol.packets import RAW_ACCEL_OK, RAW_GYRO_OK, RAW_MAG_FRESH, RAW_MAG_OK

STILL_S = 3.0  # gyro bias: still this long (device seconds)
FACE_S = 2.0  # each face: still this long
TURN_S = 30.0  # magnetometer: at most this long ...
TURN_MIN_S = 8.0  # ... and at least this long
BLOCK_S = 0.25  # stillness is judged per block of this much device time
BLOCK_MIN_SAMPLES = 3  # ... holding at least this many samples
#: The slowest RAW_SAMPLE rate whose blocks hold that many: below it the sphere is never found still.
MIN_RAW_RATE_HZ = BLOCK_MIN_SAMPLES / BLOCK_S
COVERAGE_BINS = 32
COVERAGE_TARGET = 0.75  # 24 of 32 direction bins
FACE_MIN_COS = 0.9  # an axis counts as up within about 25°
#: The weakest field the magnetometer step accepts as the earth's: 15 µT (the earth's is 25–65 µT).
MIN_FIELD_LSB = 15.0 * chips.HMC5883L_LSB_PER_UT

#: The six faces, in the order of the accelerometer step's list: (label, axis index, sign).
FACES = (("+x up", 0, 1), ("−x up", 0, -1), ("+y up", 1, 1), ("−y up", 1, -1), ("+z up (upright)", 2, 1),
         ("−z up (upside down)", 2, -1))


@dataclass(frozen=True)
class Stillness:
    """Thresholds per axis, in LSB. The chips' noise: ITG-3200 about 0.38 °/s RMS (5.5 LSB at 14.375
    LSB/(°/s)), ADXL345 about 1–1.5 LSB at 256 LSB/g, HMC5883L about 2 LSB (2 mG) at gain 1; each
    threshold is about three times that, so a sphere lying on a table passes and a hand holding it does not.
    ``*_std``: standard deviation within a block; ``*_drift``: a block's mean against the span's first."""

    gyro_std: float = 1.0 * chips.ITG3200_LSB_PER_DPS  # 1 °/s
    gyro_drift: float = 0.5 * chips.ITG3200_LSB_PER_DPS  # 0.5 °/s
    accel_std: float = 5.0  # 20 mg
    accel_drift: float = 4.0  # 16 mg: about 0.9° of tilt
    mag_std: float = 6.0  # 0.55 µT
    mag_drift: float = 6.0  # about 1.5° of heading at a 20 µT horizontal field


STILLNESS = Stillness()


@dataclass
class Series:
    """RAW_SAMPLE values: accel and gyro at device times ``t`` (s), fresh magnetometer readings at ``mag_t``."""

    t: np.ndarray
    accel: np.ndarray
    gyro: np.ndarray
    mag_t: np.ndarray
    mag: np.ndarray

    @staticmethod
    def empty() -> "Series":
        z = np.zeros((0, 3))
        return Series(np.zeros(0), z, z, np.zeros(0), z)

    def __len__(self) -> int:
        return len(self.t)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if len(self.t) > 1 else 0.0

    def since(self, t0: float) -> "Series":
        i, k = np.searchsorted(self.t, t0), np.searchsorted(self.mag_t, t0)
        return Series(self.t[i:], self.accel[i:], self.gyro[i:], self.mag_t[k:], self.mag[k:])


class SeriesBuilder:
    """RAW_SAMPLE values gathered one packet at a time (a live session) into a :class:`Series`. Samples
    without both accelerometer and gyroscope are left out; the magnetometer only where ``mag_ok`` and
    ``mag_fresh``."""

    def __init__(self):
        self.t, self.accel, self.gyro, self.mag_t, self.mag = [], [], [], [], []

    def add(self, p, t_s: float) -> None:
        """One RAW_SAMPLE at device time ``t_s`` (seconds, unwrapped)."""
        if not (p.flags & RAW_ACCEL_OK and p.flags & RAW_GYRO_OK):
            return
        self.t.append(t_s)
        self.accel.append(p.accel)
        self.gyro.append(p.gyro)
        if p.flags & RAW_MAG_OK and p.flags & RAW_MAG_FRESH:
            self.mag_t.append(t_s)
            self.mag.append(p.mag)

    def series(self, since: float | None = None) -> Series:
        """What was gathered, from device time ``since`` on (all by default)."""
        i = 0 if since is None else bisect.bisect_left(self.t, since)
        k = 0 if since is None else bisect.bisect_left(self.mag_t, since)
        f = lambda x: np.array(x, float).reshape(-1, 3)  # noqa: E731
        return Series(np.array(self.t[i:], float), f(self.accel[i:]), f(self.gyro[i:]),
                      np.array(self.mag_t[k:], float), f(self.mag[k:]))


def series_from_packets(packets) -> Series:
    """A :class:`Series` from decoded packets (RAW_SAMPLE or DecodedPacket; others are skipped), as
    :class:`SeriesBuilder` keeps them. Device time is unwrapped (``DecodedPacket.t_us`` already is)."""
    stream = PacketStream()  # times for bare packets, unwrapped as every reader of the link does
    out = SeriesBuilder()
    for dp in packets:
        p = getattr(dp, "packet", dp)
        if dp is p:
            dp = stream.packet(p)
        if p.NAME == "RAW_SAMPLE":
            out.add(p, dp.t_us * 1e-6)
    return out.series()


@dataclass
class Span:
    """A still span: samples [start, stop) of the series, device times t0 … t1 (block edges)."""

    start: int
    stop: int
    t0: float
    t1: float

    @property
    def seconds(self) -> float:
        return self.t1 - self.t0


def _block_stats(t, x, edges):
    """Per block [edges[k], edges[k+1]): count, mean (k, 3), std (k, 3)."""
    idx = np.searchsorted(t, edges)
    n = np.diff(idx)
    c1 = np.vstack([np.zeros((1, 3)), np.cumsum(x, axis=0)]) if len(x) else np.zeros((1, 3))
    c2 = np.vstack([np.zeros((1, 3)), np.cumsum(x * x, axis=0)]) if len(x) else np.zeros((1, 3))
    s1, s2 = c1[idx[1:]] - c1[idx[:-1]], c2[idx[1:]] - c2[idx[:-1]]
    nn = np.maximum(n, 1)[:, None]
    mean = s1 / nn
    std = np.sqrt(np.maximum(s2 / nn - mean * mean, 0.0))
    return n, mean, std, idx


def still_spans(s: Series, min_s: float = 0.0, th: Stillness = STILLNESS, block_s: float = BLOCK_S) -> list[Span]:
    """Still spans of at least ``min_s`` device seconds, in time order (blocks from the first sample on;
    a last, incomplete block is not judged yet)."""
    if len(s.t) < 2:
        return []
    t0 = s.t[0]
    nblocks = int(np.floor((s.t[-1] - t0) / block_s + 1e-9))
    if nblocks < 1:
        return []
    edges = t0 + block_s * np.arange(nblocks + 1)  # block k: edges[k] <= t < edges[k + 1]
    n, g_mean, g_std, idx = _block_stats(s.t, s.gyro, edges)
    _, a_mean, a_std, _ = _block_stats(s.t, s.accel, edges)
    has_mag = len(s.mag_t) > 0
    if has_mag:
        mn, m_mean, m_std, _ = _block_stats(s.mag_t, s.mag, edges)
    expected = (max(BLOCK_MIN_SAMPLES, int(0.5 * block_s / max(np.median(np.diff(s.t)), 1e-6))) if len(s.t) > 2
                else BLOCK_MIN_SAMPLES)
    quiet = (n >= expected) & np.all(g_std <= th.gyro_std, axis=1) & np.all(a_std <= th.accel_std, axis=1)
    if has_mag:
        quiet &= (mn < 2) | np.all(m_std <= th.mag_std, axis=1)
    spans: list[Span] = []
    k = 0
    while k < nblocks:
        if not quiet[k]:
            k += 1
            continue
        j = k + 1
        while j < nblocks and quiet[j]:
            ok = (np.all(np.abs(g_mean[j] - g_mean[k]) <= th.gyro_drift)
                  and np.all(np.abs(a_mean[j] - a_mean[k]) <= th.accel_drift))
            if ok and has_mag and mn[j] >= 2 and mn[k] >= 2:
                ok = bool(np.all(np.abs(m_mean[j] - m_mean[k]) <= th.mag_drift))
            if not ok:
                break
            j += 1
        if (j - k) * block_s >= min_s - 1e-9:
            spans.append(Span(int(idx[k]), int(idx[j]), float(edges[k]), float(edges[j])))
        k = j
    return spans


def trailing_still(s: Series, th: Stillness = STILLNESS, block_s: float = BLOCK_S) -> Span | None:
    """The still span that reaches the newest complete block (the sphere is still *now*), or None."""
    spans = still_spans(s, 0.0, th, block_s)
    if not spans or len(s.t) < 2:
        return None
    last_edge = s.t[0] + block_s * int(np.floor((s.t[-1] - s.t[0]) / block_s + 1e-9))
    return spans[-1] if abs(spans[-1].t1 - last_edge) < 1e-6 else None


def classify_face(accel_mean, min_cos: float = FACE_MIN_COS) -> int | None:
    """Index into :data:`FACES` of the axis pointing up, or None when no axis is within ~25° of vertical."""
    a = np.asarray(accel_mean, float)
    norm = np.linalg.norm(a)
    if norm < 0.5 * chips.ADXL345_LSB_PER_G:
        return None
    i = int(np.argmax(np.abs(a)))
    if abs(a[i]) < min_cos * norm:
        return None
    return 2 * i + (0 if a[i] > 0 else 1)


@dataclass
class FaceSeen:
    face: int
    mean: np.ndarray  # mean accelerometer reading (LSB) over the span
    span: Span
    samples: int


@dataclass
class FaceNow:
    """What the sphere is doing now, for the progress line."""

    still_s: float  # how long it has been still (0 = moving)
    face: int | None  # the face up while still (None: moving, or not flat on a face)


def update_faces(seen: dict, s: Series, face_s: float = FACE_S, th: Stillness = STILLNESS) -> tuple[dict, FaceNow]:
    """The accelerometer step after new samples: ``seen`` (face index → :class:`FaceSeen`) with the face
    the sphere has lain still on for ``face_s`` now added (or replacing an older sighting of the same
    face: the newest, longest span wins). Returns a new dict and what the sphere is doing now."""
    span = trailing_still(s, th)
    if span is None:
        return dict(seen), FaceNow(0.0, None)
    mean = s.accel[span.start:span.stop].mean(axis=0)
    face = classify_face(mean)
    out = dict(seen)
    if face is not None and span.seconds >= face_s - 1e-9:
        out[face] = FaceSeen(face, mean, span, span.stop - span.start)
    return out, FaceNow(span.seconds, face)


def missing_faces(seen) -> list[str]:
    return [FACES[i][0] for i in range(6) if i not in seen]


@functools.lru_cache(maxsize=None)
def direction_bins(n: int = COVERAGE_BINS) -> np.ndarray:
    """``n`` unit vectors spread evenly over the sphere (Fibonacci lattice); each is the centre of a bin."""
    i = np.arange(n) + 0.5
    polar = np.arccos(1.0 - 2.0 * i / n)
    azim = np.pi * (1.0 + 5.0 ** 0.5) * i
    bins = np.stack([np.cos(azim) * np.sin(polar), np.sin(azim) * np.sin(polar), np.cos(polar)], 1)
    bins.flags.writeable = False  # shared by every caller
    return bins


def cloud_centre(mag) -> np.ndarray:
    """Centre of a magnetometer cloud: a least-squares sphere fit (‖x‖² = 2 c·x + k), or the per-axis
    mid-range when the fit is ill-posed (too few readings, or they lie on a ring)."""
    x = np.asarray(mag, float)
    if len(x) == 0:
        return np.zeros(3)
    mid = (x.max(axis=0) + x.min(axis=0)) / 2.0
    if len(x) < 10:
        return mid
    A = np.column_stack([2.0 * x, np.ones(len(x))])
    sol, _, rank, _ = np.linalg.lstsq(A, np.sum(x * x, axis=1), rcond=None)
    c = sol[:3]
    r2 = sol[3] + c @ c
    spread = np.linalg.norm(x - mid, axis=1).max()
    if rank < 4 or r2 <= 0 or np.sqrt(r2) > 3.0 * max(spread, 1.0) or np.linalg.norm(c - mid) > 2.0 * max(spread, 1.0):
        return mid
    return c


@dataclass
class Coverage:
    fraction: float
    bins_hit: int
    n_bins: int
    hit: np.ndarray = field(repr=False, default=None)


def field_coverage(mag, n_bins: int = COVERAGE_BINS, centre=None, min_radius: float = MIN_FIELD_LSB) -> Coverage:
    """Fraction of direction bins holding at least one reading. Directions are taken from ``centre``
    (by default :func:`cloud_centre` of the readings) and count only for readings whose distance from it
    is within 30 % of the median distance, which must be at least ``min_radius`` LSB: a cloud that is
    still a small blob (the sphere has hardly turned) covers nothing, however its noise points.
    Overflowed readings (−4096) are left out."""
    x = np.asarray(mag, float).reshape(-1, 3)
    x = x[np.all(x != chips.HMC5883L_OVERFLOW, axis=1)]
    hit = np.zeros(n_bins, bool)
    if len(x) < 10:
        return Coverage(0.0, 0, n_bins, hit)
    c = cloud_centre(x) if centre is None else np.asarray(centre, float)
    d = x - c
    norm = np.linalg.norm(d, axis=1)
    r = float(np.median(norm))
    if r < min_radius:
        return Coverage(0.0, 0, n_bins, hit)
    keep = np.abs(norm - r) <= 0.3 * r
    d = d[keep] / norm[keep, None]
    if len(d):
        hit[np.unique(np.argmax(d @ direction_bins(n_bins).T, axis=1))] = True
    return Coverage(float(hit.mean()), int(hit.sum()), n_bins, hit)


@dataclass
class TurnStatus:
    coverage: Coverage
    seconds: float  # device seconds recorded
    done: bool
    reason: str  # "coverage", "time" or "" (not done)


def turn_status(s: Series, min_s: float = TURN_MIN_S, max_s: float = TURN_S, target: float = COVERAGE_TARGET,
                n_bins: int = COVERAGE_BINS) -> TurnStatus:
    """The magnetometer step: done when the field directions cover ``target`` of the bins and ``min_s``
    have passed, or when ``max_s`` have passed (device time)."""
    cov = field_coverage(s.mag, n_bins)
    secs = s.duration
    if secs >= min_s and cov.fraction >= target:
        return TurnStatus(cov, secs, True, "coverage")
    if secs >= max_s:
        return TurnStatus(cov, secs, True, "time")
    return TurnStatus(cov, secs, False, "")


def calibrate(gyro_still, face_means: dict, mag) -> calibration.Calibration:
    """The three fits on what the steps collected; a part that cannot be computed is left None with a note."""
    cal = calibration.Calibration()
    try:
        cal.gyro = calibration.gyro_bias(gyro_still)
    except ValueError as e:
        cal.notes.append(f"gyro: {e}")
    if len(face_means) >= 6:
        try:
            cal.accel = calibration.accel_six_position(np.array([face_means[k] for k in sorted(face_means)]))
        except ValueError as e:
            cal.notes.append(f"accel: {e}")
    else:
        cal.notes.append(f"accel: faces not seen: {', '.join(missing_faces(face_means))}")
    try:
        cal.mag = calibration.mag_ellipsoid(mag)
    except ValueError as e:
        cal.notes.append(f"mag: {e}")
    return cal


def from_series(s: Series, still_min_s: float = 1.0, face_s: float = FACE_S) -> tuple[calibration.Calibration, dict]:
    """A whole recording at once (``--capture``): the gyro bias from every still span of ``still_min_s``
    or more, each face from its longest still span of ``face_s`` or more (the same detection as the
    guided steps), the magnetometer from every fresh reading. Returns the calibration and the faces seen."""
    spans = still_spans(s, still_min_s)
    still = np.concatenate([s.gyro[sp.start:sp.stop] for sp in spans]) if spans else np.zeros((0, 3))
    faces: dict = {}
    for sp in spans:
        if sp.seconds < face_s - 1e-9:
            continue
        mean = s.accel[sp.start:sp.stop].mean(axis=0)
        f = classify_face(mean)
        if f is not None and (f not in faces or sp.seconds > faces[f].span.seconds):
            faces[f] = FaceSeen(f, mean, sp, sp.stop - sp.start)
    cal = calibrate(still, {k: v.mean for k, v in faces.items()}, s.mag)
    if not spans:
        cal.notes.insert(0, f"gyro: no still span of {still_min_s:g} s or more")
    return cal, faces
