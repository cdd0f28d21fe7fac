"""What a capture from the board says: hello, stream rates, events, status, decoder counters; and the
firmware's orientation against BROAD's optical reference (the dataset's metric) beside the host's
double-precision Madgwick on the same quantised samples."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sphere import quaternion as quat
from sphere.broad import error_angles_deg, orientation_error
from sphere.chips import ITG3200_LSB_PER_DPS
from sphere.fusion.common import ecompass
from sphere.fusion.madgwick import madgwick_step
from sphere.protocol.decoder import decode_all
from sphere.protocol.packets import (
    ORI_ACCEL_REJECTED,
    ORI_CONVERGING,
    ORI_MAG_REJECTED,
    ORI_MAG_USED,
    ORI_PREV_SHIFT,
    RAW_ACCEL_OK,
    RAW_ACCEL_STALE,
    RAW_GYRO_OK,
    RAW_GYRO_STALE,
    RAW_MAG_OK,
    RAW_TAP_ACTIVE,
    Event,
    Hello,
    Orientation,
    RawSample,
    Status,
)
from sphere.protocol.timebase import WRAP_US, TimeUnwrapper

_ORI_NOW = ORI_MAG_USED | ORI_ACCEL_REJECTED | ORI_MAG_REJECTED  # this update's inputs
_ORI_PREV = _ORI_NOW << ORI_PREV_SHIFT  # the same bits of the update one period before


@dataclass
class CaptureSummary:
    hello: Hello | None
    hellos: int
    raw: list = field(default_factory=list)
    orientation: list = field(default_factory=list)
    events: list = field(default_factory=list)
    status: list = field(default_factory=list)
    decoder: dict = field(default_factory=dict)

    @staticmethod
    def rate_hz(packets) -> float | None:
        """Packets per second of device time. A reset starts the device's clock again: each run between
        restarts is a span of its own (the time spent restarting is in no span), and the spans add up."""
        intervals, span_us = 0, 0
        prev = None
        for p in packets:
            if prev is not None:
                step = (p.t_us - prev) % WRAP_US  # forward, also across the u32 wrap
                if step < WRAP_US // 2:  # forward; a step back (the clock started again) comes out above half
                    intervals += 1
                    span_us += step
            prev = p.t_us
        return intervals / (span_us * 1e-6) if span_us > 0 else None

    @property
    def raw_rate_hz(self) -> float | None:
        return self.rate_hz(self.raw)

    @property
    def orientation_rate_hz(self) -> float | None:
        return self.rate_hz(self.orientation)

    def events_named(self, name: str) -> list:
        return [e for e in self.events if e.event_name == name]

    def as_dict(self) -> dict:
        h = self.hello
        return {
            "hello": h.to_json() if h else None,
            "hellos": self.hellos,
            "raw_samples": len(self.raw),
            "raw_rate_hz": self.raw_rate_hz,
            "orientations": len(self.orientation),
            "orientation_rate_hz": self.orientation_rate_hz,
            "events": {n: len(self.events_named(n)) for n in ("single_tap", "double_tap", "free_fall")},
            "status_packets": len(self.status),
            "last_status": self.status[-1].to_json() if self.status else None,
            "decoder": self.decoder,
        }


def summarise(data: bytes | Path | str) -> CaptureSummary:
    if not isinstance(data, (bytes, bytearray)):
        data = Path(data).read_bytes()
    packets, stats = decode_all(bytes(data))
    hellos = [p for p in packets if isinstance(p, Hello)]
    return CaptureSummary(
        hello=hellos[0] if hellos else None,
        hellos=len(hellos),
        raw=[p for p in packets if isinstance(p, RawSample)],
        orientation=[p for p in packets if isinstance(p, Orientation)],
        events=[p for p in packets if isinstance(p, Event)],
        status=[p for p in packets if isinstance(p, Status)],
        decoder=stats.as_dict(),
    )


# ---------------------------------------------------------------- accuracy against BROAD


def _held(t_src_s: np.ndarray, values: np.ndarray, t_query_s: np.ndarray) -> np.ndarray:
    """The newest value at or before each query time; NaN before the first."""
    idx = np.searchsorted(t_src_s, t_query_s, side="right") - 1
    out = np.full((len(t_query_s), values.shape[1]), np.nan)
    ok = idx >= 0
    out[ok] = values[idx[ok]]
    return out


STARTUP_BETA = 1.0  # the firmware's STARTUP_BETA_MILLI (firmware/src/core/marg_filter.h), while `converging`
# the firmware's power-up gyro bias estimate (firmware/src/core/sphere_device.h, gyro_bias.h)
STARTUP_BIAS_SAMPLES = 200
STARTUP_BIAS_TRIES = 10
GYRO_SPAN_LSB, ACCEL_SPAN_LSB, MAG_SPAN_LSB = 58, 24, 96
MAG_DRIFT_LSB = 4  # the window's second-half magnetometer mean within this of the first half's (gyro_bias.h)
# ORIENTATION carries the state predicted this far ahead at the update's rate (SphereDevice::GYRO_DELAY_US)
GYRO_DELAY_S = 0.0033


def _moved_at(raw: list, idx) -> int | None:
    """The firmware's stillness test (gyro_bias.cpp) over the readings raw[i] for i in idx: every gyro and
    accelerometer reading within ±span/2 of the window's first, every magnetometer reading (when present)
    within ±MAG_SPAN_LSB/2 of it, and the means of the present magnetometer readings over the window's first
    and second half (index < n/2, ≥ n/2) within MAG_DRIFT_LSB of each other on every axis (compared
    multiplied out, |Σ₁·n₂ − Σ₂·n₁| ≤ MAG_DRIFT_LSB·n₁·n₂, as the firmware does). Returns
    the position in idx of the first reading that moved (the last one when only the halves differ), or None
    when the window was still."""
    half = (GYRO_SPAN_LSB // 2, ACCEL_SPAN_LSB // 2, MAG_SPAN_LSB // 2)

    def near(v, ref, h):
        return all(-h <= int(a) - int(b) <= h for a, b in zip(v, ref))

    first = raw[idx[0]]
    mag_ref = first.mag if first.flags & RAW_MAG_OK else (0, 0, 0)
    n = len(idx)
    sums, counts = [[0, 0, 0], [0, 0, 0]], [0, 0]
    for j, i in enumerate(idx):
        p = raw[i]
        if not (near(p.gyro, first.gyro, half[0]) and near(p.accel, first.accel, half[1])
                and (not p.flags & RAW_MAG_OK or near(p.mag, mag_ref, half[2]))):
            return j
        if p.flags & RAW_MAG_OK:
            h = int(j >= n // 2)
            counts[h] += 1
            sums[h] = [s + int(v) for s, v in zip(sums[h], p.mag)]
    n1, n2 = counts
    lim = MAG_DRIFT_LSB * n1 * n2
    return n - 1 if any(abs(a * n2 - b * n1) > lim for a, b in zip(*sums)) else None


def _mean_lsb(raw: list, idx) -> list[int]:
    """The firmware's rounding of a window's mean: half away from zero, then C division."""
    total = np.sum([raw[i].gyro for i in idx], axis=0)
    n = len(idx)
    return [int((t + n // 2 if t >= 0 else t - n // 2) / n) for t in total.tolist()]


def _startup_windows(raw: list):
    """The power-up windows: (index from which the estimate applies, bias) or (None, index after the last
    window) when all STARTUP_BIAS_TRIES moved or the readings ran out."""
    i, tries = 0, 1
    while i + STARTUP_BIAS_SAMPLES <= len(raw):
        moved = _moved_at(raw, range(i, i + STARTUP_BIAS_SAMPLES))
        if moved is None:
            return i + STARTUP_BIAS_SAMPLES - 1, _mean_lsb(raw, range(i, i + STARTUP_BIAS_SAMPLES))
        i += moved + 1
        if tries >= STARTUP_BIAS_TRIES:
            return None, i
        tries += 1
    return None, len(raw)


def firmware_startup_bias(raw: list):
    """The firmware's power-up gyro bias estimate replayed on the RAW_SAMPLEs it sent (gyro_bias.cpp and
    SphereDevice::tick): windows of STARTUP_BIAS_SAMPLES readings, still when every gyro, accelerometer and
    (when present) magnetometer reading stays within ±span/2 of the window's first; a window that moves
    ends at the moving reading and the next starts at the reading after it, STARTUP_BIAS_TRIES windows at
    most. Returns (index of the reading from which the firmware applies it, bias in LSB rounded half away
    from zero) or None. Assumes a device without a stored calibration (the simulator's blank EEPROM)."""
    k, bias = _startup_windows(raw)
    return None if k is None else (k, bias)


TRACK_SAMPLES, TRACK_STEP_LSB = 200, 2  # the firmware's bias tracking (SphereDevice::trackBias)


def firmware_bias_schedule(raw: list) -> list[tuple[int, list[int]]]:
    """Every gyro bias the firmware used, replayed on its RAW_SAMPLEs: the power-up estimate
    (:func:`firmware_startup_bias`), then the tracking windows SphereDevice::trackBias runs whenever no other
    estimate does: windows of TRACK_SAMPLES readings with the same stillness test, each moving the bias
    by at most TRACK_STEP_LSB per axis towards its mean (all the way when no bias was found at power-up);
    a window that moves ends at the moving reading and the next starts after it. Readings with the gyro
    missing or stale (flags bit 1 clear, or bit 5/6 set) are skipped as the firmware skips them.
    Returns [(index of the reading from which a bias applies, bias in LSB)], in order."""
    k, found = _startup_windows(raw)
    out = [] if k is None else [(k, found)]
    start, bias = (k + 1, list(found)) if k is not None else (found, None)
    n = TRACK_SAMPLES
    usable = [i for i in range(start, len(raw)) if raw[i].flags & RAW_GYRO_OK
              and not raw[i].flags & (RAW_ACCEL_STALE | RAW_GYRO_STALE)]
    j = 0
    while j + n <= len(usable):
        window = usable[j:j + n]
        moved = _moved_at(raw, window)
        if moved is not None:
            j += moved + 1
            continue
        est = _mean_lsb(raw, window)
        bias = est if bias is None else [b + max(-TRACK_STEP_LSB, min(TRACK_STEP_LSB, e - b)) for b, e in zip(bias, est)]
        out.append((window[-1], list(bias)))
        j += n
    return out


#: the first firmware that sends RAW_SAMPLE before its magnetometer poll (protocol/spec.md §4.2): its update k uses the
#: magnetometer reading RAW_SAMPLE k+1 carries
MAG_AFTER_RAW_FIRMWARE = (0, 3, 3)


def mag_after_raw(hello) -> bool:
    """Whether the firmware of this HELLO polls the magnetometer after sending the period's RAW_SAMPLE."""
    return hello is not None and tuple(hello.firmware_version) >= MAG_AFTER_RAW_FIRMWARE


def host_madgwick(raw: list, imu_rate_hz: float, beta: float, bias_s: float = 0.0, orientation: list | None = None,
                  startup_beta: float = STARTUP_BETA, mag_lag: bool = False):
    """The host's double-precision Madgwick on the RAW_SAMPLE values the firmware read.

    Returns (t_s, q_nwu). ``bias_s`` > 0: subtract
    the mean gyro of the first ``bias_s`` seconds; following the firmware, its power-up estimate exactly
    (:func:`firmware_startup_bias`, from the reading where the firmware starts applying it) and the
    changes its bias tracking made later (:func:`firmware_bias_schedule`).
    With ``orientation`` (the firmware's ORIENTATION packets) the host takes the firmware's decisions
    sample by sample, so that only the arithmetic differs: the accelerometer is left out where the
    firmware flagged a tap (RAW_SAMPLE ``tap_active``) or ``accel_rejected``, the magnetometer where it
    was missing or ``mag_rejected`` (gravity-only), β is ``startup_beta`` while ``converging``, and the
    state starts at the identity as the firmware's does (without ``orientation``: at the e-compass), and
    each output is the state predicted GYRO_DELAY_S ahead at that sample's rate, as ORIENTATION carries it.
    ``mag_lag`` (firmware 0.3.3 on, :func:`mag_after_raw`): a RAW_SAMPLE carries the magnetometer as the previous
    period's poll left it, while the firmware's update of that period used its own poll, which the next RAW_SAMPLE
    carries; so sample i takes sample i+1's magnetometer and its ``mag_ok`` (the last sample keeps its own).
    The flags of a raw sample without its own ORIENTATION packet are the next packet's "previous update"
    bits (protocol v2, flags bits 5-7) when that packet belongs to the next raw sample, else those of the
    newest packet before it.
    """
    un = TimeUnwrapper()
    t_us = np.array([un(p.t_us) for p in raw])
    t = t_us * 1e-6
    gyr = np.radians(np.array([p.gyro_dps for p in raw], dtype=float))
    acc = np.array([p.accel_g for p in raw], dtype=float)
    mag = np.array([p.mag_uT for p in raw], dtype=float)
    rflags = np.array([p.flags for p in raw], dtype=int)
    mag_ok = rflags & RAW_MAG_OK
    if mag_lag and len(raw) > 1:
        mag = np.vstack([mag[1:], mag[-1:]])
        mag_ok = np.append(mag_ok[1:], mag_ok[-1])
    if bias_s > 0 and orientation:
        # the firmware's biases as it changed them: power-up estimate, then tracking while still
        applied = np.zeros(3)
        for k, bias_lsb in firmware_bias_schedule(raw):
            b = np.radians(np.asarray(bias_lsb, dtype=float) / ITG3200_LSB_PER_DPS)
            gyr[k:] -= b - applied
            applied = b
    elif bias_s > 0:
        first = t < t[0] + bias_s
        gyr = gyr - gyr[first].mean(axis=0)
    acc_valid = (rflags & RAW_ACCEL_OK).astype(bool) & ~(rflags & RAW_TAP_ACTIVE).astype(bool)
    mag_valid = mag_ok.astype(bool)
    betas = np.full(len(raw), float(beta))
    if orientation:
        uo = TimeUnwrapper()
        t_o = np.array([uo(o.t_us) for o in orientation])
        of = np.array([o.flags for o in orientation], dtype=int)
        idx = np.searchsorted(t_o, t_us, side="right") - 1
        has = idx >= 0
        f = np.where(has, of[np.clip(idx, 0, None)], 0)
        if (of & _ORI_PREV).any():
            # protocol v2: a raw sample without its own ORIENTATION is the update the next packet calls
            # "previous" (flags bits 5-7), when that packet is the next raw sample's
            nxt = np.clip(idx + 1, 0, len(t_o) - 1)
            own = has & (t_o[np.clip(idx, 0, None)] == t_us)
            t_next_raw = np.append(t_us[1:], -1)
            use = ~own & (idx + 1 < len(t_o)) & (t_o[nxt] == t_next_raw)
            f = np.where(use, (f & ~_ORI_NOW) | ((of[nxt] & _ORI_PREV) >> ORI_PREV_SHIFT), f)
        acc_valid &= ~((f & ORI_ACCEL_REJECTED).astype(bool) & has)
        mag_valid &= ~(((f & ORI_MAG_REJECTED).astype(bool) | ~(f & ORI_MAG_USED).astype(bool)) & has)
        betas = np.where(has & (f & ORI_CONVERGING).astype(bool), startup_beta, betas)
    # following the firmware, start where it starts (identity, converging at the start-up gain);
    # on its own, from the e-compass of the first sample as `sphere eval` does
    q = (1.0, 0.0, 0.0, 0.0) if orientation else ecompass(*acc[0], *mag[0], frame="NWU")
    dt = 1.0 / imu_rate_hz
    out = np.empty((len(raw), 4))
    g, a, m = gyr.tolist(), acc.tolist(), mag.tolist()
    av, mv, bl = acc_valid.tolist(), mag_valid.tolist(), betas.tolist()
    for i in range(len(raw)):
        gi, ai, mi = g[i], a[i], m[i]
        if mv[i]:
            q = madgwick_step(q, gi[0], gi[1], gi[2], ai[0], ai[1], ai[2], mi[0], mi[1], mi[2], dt, bl[i], av[i], True)
        else:
            q = madgwick_step(q, gi[0], gi[1], gi[2], ai[0], ai[1], ai[2], None, None, None, dt, bl[i], av[i], False)
        out[i] = q
    if orientation:
        # what the firmware sends: the state GYRO_DELAY_S ahead at the update's rate (0 without a gyro),
        # q + ½ q ⊗ [0, ω]·τ normalised (MargFilter::predictQ14)
        w = np.where((rflags & RAW_GYRO_OK).astype(bool)[:, None], gyr, 0.0) * (0.5 * GYRO_DELAY_S)
        p0, p1, p2, p3 = out.T
        wx, wy, wz = w.T
        pred = np.stack([p0 - p1 * wx - p2 * wy - p3 * wz, p1 + p0 * wx + p2 * wz - p3 * wy,
                         p2 + p0 * wy - p1 * wz + p3 * wx, p3 + p0 * wz + p1 * wy - p2 * wx], axis=1)
        out = pred / np.linalg.norm(pred, axis=1, keepdims=True)
    return t, out


@dataclass
class AccuracyRow:
    trial: str
    seconds: float
    firmware: dict | None
    host: dict | None
    fw_vs_host_rms_deg: float | None
    note: str = ""


def accuracy(summary: CaptureSummary, trial, offset_s: float, beta: float, bias_s: float = 0.0,
             follow_firmware: bool = True) -> AccuracyRow:
    """The dataset's metric for the firmware's quaternions and the host Madgwick's on one trial slice.

    ``trial`` is the slice of the BROAD trial that was played; its sample i was played at simulated
    time ``offset_s + i / rate`` (``offset_s`` = the still lead-in held before it).
    """
    t_trial = offset_s + np.arange(len(trial)) / trial.rate_hz
    notes = []
    fw = None
    q_fw_enu = None
    if summary.orientation:
        un = TimeUnwrapper()
        t_o = np.array([un(p.t_us) for p in summary.orientation]) * 1e-6
        q_o = np.array([p.quat_float for p in summary.orientation], dtype=float)
        q_fw_enu = quat.nwu_to_enu(quat.normalize(_held(t_o, q_o, t_trial)))
        try:
            fw = orientation_error(q_fw_enu, trial).as_dict()
        except ValueError as e:
            notes.append(str(e))
    else:
        notes.append("no ORIENTATION packets in the capture")
    host = None
    q_h_enu = None
    imu_rate = summary.hello.imu_rate_hz if summary.hello else 200
    hm = host_madgwick(summary.raw, imu_rate, beta, bias_s,
                       orientation=summary.orientation if follow_firmware else None,
                       mag_lag=follow_firmware and mag_after_raw(summary.hello)) if summary.raw else None
    if hm is None:
        notes.append("host Madgwick unavailable (no RAW_SAMPLE packets)")
    else:
        t_h, q_h = hm
        if q_fw_enu is not None:
            # the host's q after the raw sample of each ORIENTATION packet's tick, held in between as the
            # firmware's column is: both columns then carry the same stream-rate hold (100 Hz by default),
            # and their difference is the filters' alone
            q_h_at_o = _held(t_h, q_h, t_o + 1e-7)
            q_h_enu = quat.nwu_to_enu(_held(t_o, q_h_at_o, t_trial))
        else:
            q_h_enu = quat.nwu_to_enu(_held(t_h, q_h, t_trial))
        try:
            host = orientation_error(q_h_enu, trial).as_dict()
        except ValueError as e:
            notes.append(str(e))
    diff = None
    if q_fw_enu is not None and hm is not None:
        # at the ORIENTATION packets' own times, so that the packets held between ticks do not count as a
        # difference during rotation
        ok = np.all(np.isfinite(q_h_at_o), axis=1)
        if ok.any():
            tot, _, _ = error_angles_deg(quat.nwu_to_enu(quat.normalize(q_o[ok])), quat.nwu_to_enu(q_h_at_o[ok]))
            diff = float(np.sqrt(np.mean(tot * tot)))
    return AccuracyRow(trial.name, len(trial) / trial.rate_hz, fw, host, diff, "; ".join(notes))


def accuracy_table(rows: list[AccuracyRow]) -> str:
    def f(d, k):
        return f"{d[k]:.2f}" if d and d.get(k) is not None and math.isfinite(d[k]) else "–"

    lines = [
        "| trial | s | firmware total ° | heading ° | inclination ° | host Madgwick total ° | heading ° | inclination ° | firmware vs host RMS ° |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r.trial} | {r.seconds:.0f} | {f(r.firmware, 'total')} | {f(r.firmware, 'heading')} | "
            f"{f(r.firmware, 'inclination')} | {f(r.host, 'total')} | {f(r.host, 'heading')} | "
            f"{f(r.host, 'inclination')} | {'–' if r.fw_vs_host_rms_deg is None else f'{r.fw_vs_host_rms_deg:.2f}'} |")
    fw = [r.firmware["total"] for r in rows if r.firmware]
    ho = [r.host["total"] for r in rows if r.host]
    if len(rows) > 1:
        lines.append(f"| mean | | {np.mean(fw):.2f} | | | {np.mean(ho):.2f} | | | |" if fw and ho else "| mean | | | | | | | | |")
    for r in rows:
        if r.note:
            lines.append(f"\n{r.trial}: {r.note}")
    return "\n".join(lines)
