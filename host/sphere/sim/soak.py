"""`sphere sim --soak`: the real firmware on BROAD motion under a seeded schedule of every fault the board
can make, judged from the device's bytes alone against a fault-free run of the same motion.

The board records the simulated time of every frame delimiter it captures (``--capture-times``), so a
frame of the stream can be placed in simulated time, and the faults it injected (its ``faults`` log);
everything else comes from the captured bytes: sequence numbers, device timestamps, CRCs, RAW_SAMPLE flags
and ORIENTATION quaternions. The invariants (issue 11) and their limits are in :data:`LIMITS`.
"""

from __future__ import annotations

import bisect
import json
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sphere import quaternion as quat
from sphere.broad import load_trial, trial_paths
from sphere.protocol import encode_frame, packets
from sphere.protocol.decoder import FrameDecoder
from sphere.protocol.packets import (
    ORI_CONVERGING,
    RAW_ACCEL_OK,
    RAW_ACCEL_STALE,
    RAW_GYRO_OK,
    RAW_GYRO_STALE,
    RAW_MAG_FRESH,
    RAW_MAG_OK,
    RAW_MAG_STALE,
    Hello,
    Orientation,
    RawSample,
    Status,
)
from sphere.sim import trace as T
from sphere.sim.board import run_board

#: Limits of the invariants: stale frames and CRC errors outside injected line faults must be 0; a sensor
#: must give fresh data within these times of a fault's end (a reset needs the firmware to start again);
#: 2 s after a fault the device's orientation must be within this of the fault-free run's.
LIMITS = {"recovery_ms": 100.0, "recovery_after_reset_ms": 1000.0, "orientation_excess_deg": 2.0}

#: Fault kinds of the schedule (all by default); see :func:`schedule`.
FAULT_KINDS = ("nack", "stall", "glitch", "brownout", "reset_mid_read", "sda_held", "host_stall")

#: a chip's RAW_SAMPLE flags: fresh data needs all of ``need`` set and ``stale`` (protocol v2: the value is held
#: from the last good read; 0 in v1 streams) clear
CHIP_FLAGS = {"adxl345": {"need": RAW_ACCEL_OK, "stale": RAW_ACCEL_STALE},
              "itg3200": {"need": RAW_GYRO_OK, "stale": RAW_GYRO_STALE},
              "hmc5883l": {"need": RAW_MAG_OK | RAW_MAG_FRESH, "stale": RAW_MAG_STALE},
              "qmc5883l": {"need": RAW_MAG_OK | RAW_MAG_FRESH, "stale": RAW_MAG_STALE}}
LEAD_IN_S = 3.0  # still at power-up: the firmware's gyro bias window
RESET_KINDS = ("brownout", "reset_mid_read")
LINE_WINDOW_S = 0.05  # a reset cuts the frame on the wire; a host stall drops bytes up to its end


@dataclass
class Frame:
    t_s: float  # simulated time of its delimiter
    ok: bool
    packet: object = None  # decoded packet (good frames of a known type)
    type_: int | None = None
    seq: int | None = None


def read_frames(capture: bytes, times: bytes) -> list[Frame]:
    """Every delimited chunk of the capture as a frame, placed in simulated time by the board's
    --capture-times records (one per delimiter, in order). Decoded by the protocol's FrameDecoder one chunk at
    a time, repeats kept (a repeated frame is what the stale-frame check looks for)."""
    rec = np.frombuffer(times, dtype=[("off", "<u8"), ("t", "<f8")])
    decoder = FrameDecoder(duplicate_window=0)
    stats = decoder.stats
    out = []
    start = 0
    for i, t in enumerate(rec["t"]):
        end = int(rec["off"][i])  # one past the delimiter
        chunk = capture[start:end]
        start = end
        if len(chunk) < 2:
            continue
        bad = stats.oversize + stats.framing_errors + stats.crc_errors
        packets = decoder.feed(chunk)
        if stats.oversize + stats.framing_errors + stats.crc_errors != bad:
            out.append(Frame(float(t), False))
            continue
        pkt = packets[0] if packets else None  # None: a good frame of a type or length this host does not know
        out.append(Frame(float(t), True, pkt, pkt.TYPE if pkt else None, pkt.seq if pkt else None))
    return out


@dataclass
class Invariant:
    count: float = 0
    first_s: float | None = None
    detail: str = ""

    def add(self, t_s: float, n: float = 1, detail: str = "") -> None:
        if self.first_s is None:
            self.first_s = round(t_s, 4)
            self.detail = detail
        self.count += n

    def as_dict(self) -> dict:
        return {"count": self.count, "first_s": self.first_s, "detail": self.detail}


def _in(t, windows) -> bool:
    return any(a <= t <= b for a, b in windows)


def stream_checks(frames: list[Frame], line_windows, resets_t=()) -> dict:
    """stale_frames, crc_errors (outside ``line_windows``), frames_dropped, resets, overruns. A packet whose
    device time starts again from an injected reset (its HELLO lost while the host was not reading) is a
    restart, not a stale frame."""
    stale, crc, dropped = Invariant(), Invariant(), Invariant()
    last_seq = None
    last_t: dict[int, int] = {}
    hellos = hellos_lost = 0
    overruns_by_boot = [0]
    for f in frames:
        if not f.ok:
            if not _in(f.t_s, line_windows):
                crc.add(f.t_s, detail="a frame with a bad CRC or COBS code outside injected line faults")
            continue
        p = f.packet
        if p is None:
            continue
        if isinstance(p, Hello) and f.seq == 0:
            hellos += 1
            last_seq, last_t = None, {}
            overruns_by_boot.append(0)
            continue
        t_us = getattr(p, "t_us", None)
        prev = last_t.get(f.type_) if t_us is not None else None
        if prev is not None and ((t_us - prev) & 0xFFFFFFFF) >= 0x80000000:
            if any(abs(f.t_s - t_us * 1e-6 - r) < 0.5 for r in resets_t):
                hellos_lost += 1  # the device started again at an injected reset; its HELLO was not received
                last_seq, last_t = None, {}
                overruns_by_boot.append(0)
                prev = None
            else:
                stale.add(f.t_s, detail=f"{type(p).__name__} time {t_us} us after {prev} us without a HELLO")
                continue
        # 8-bit sequence numbers: the same number again, or a jump of 128 or more, is a repeat unless the
        # device's time moved on (then frames were lost, e.g. while the host did not read: exactly 256 of them
        # bring the same number back)
        forward_in_time = prev is not None and t_us != prev
        if last_seq is not None:
            d = (f.seq - last_seq) & 0xFF
            if (d == 0 or d >= 128) and not forward_in_time:
                stale.add(f.t_s, detail=f"seq {f.seq} after {last_seq}")
                continue
            d = d or 256
            if d > 1:
                dropped.add(f.t_s, d - 1)
        last_seq = f.seq
        if t_us is not None:
            last_t[f.type_] = t_us
        if isinstance(p, Status):
            overruns_by_boot[-1] = max(overruns_by_boot[-1], p.loop_overruns)
    return {"stale_frames": stale, "crc_errors": crc, "frames_dropped": dropped,
            "hellos": hellos, "hellos_lost": hellos_lost, "overruns": sum(overruns_by_boot)}


def fault_ends(faults: list[dict], chips: list[str]) -> list[dict]:
    """The end of each injected fault, with the chips it took away: [{kind, t_end, chips, reset}]."""
    out = []
    starts = {}
    for f in faults:
        k, t, chip = f["kind"], f["t"], f.get("chip")
        if k in ("nack_start", "stall_start", "host_stall"):
            starts[(k.split("_")[0], chip)] = t
        elif k == "nack_end":
            out.append({"kind": "nack", "t_start": starts.pop(("nack", chip), t), "t_end": t, "chips": [chip]})
        elif k == "stall_end":
            out.append({"kind": "stall", "t_start": starts.pop(("stall", None), t), "t_end": t, "chips": chips})
        elif k == "glitch_nack":
            out.append({"kind": k, "t_start": t, "t_end": t, "chips": [chip]})
        elif k == "clock_stretch":
            out.append({"kind": k, "t_start": t, "t_end": t, "chips": chips})
        elif k in RESET_KINDS or k == "sda_held_at_power_up":
            out.append({"kind": k, "t_start": t, "t_end": t, "chips": chips})
    return out


def recovery(frames: list[Frame], ends: list[dict], host_stalls=()) -> tuple[Invariant, list]:
    """sensor_recovery_ms: the longest time from a fault's end to its sensor's fresh data in RAW_SAMPLE: its
    ``_ok`` flag set and its ``_stale`` flag clear (``mag_fresh`` too for the magnetometer)."""
    raw_t = np.array([f.t_s for f in frames if isinstance(f.packet, RawSample)])
    raw_flags = np.array([f.packet.flags for f in frames if isinstance(f.packet, RawSample)], dtype=int)
    worst = Invariant()
    rows = []
    restarts = [(r["t_end"], r["kind"]) for r in ends if r["kind"] in RESET_KINDS + ("sda_held_at_power_up",)]
    for e in ends:
        resetting = e["kind"] in RESET_KINDS + ("sda_held_at_power_up",)
        # a reset between this fault's start and the end of its allowance restarts the firmware: the sensors'
        # fresh data then waits for the start-up, which that reset's own row judges against its limit
        overtaken = None if resetting else next(
            (k for t, k in restarts if e["t_start"] <= t <= e["t_end"] + LIMITS["recovery_ms"] / 1e3), None)
        for chip in e["chips"]:
            need, stale = CHIP_FLAGS[chip]["need"], CHIP_FLAGS[chip]["stale"]
            # while the host was not reading, the sensor's fresh samples may have been lost on the way:
            # count from the end of that stall
            t0 = max([e["t_end"]] + [b for a, b in host_stalls if a <= e["t_end"] <= b])
            i0 = np.searchsorted(raw_t, t0)
            f = raw_flags[i0:]
            ok = np.nonzero(((f & need) == need) & ((f & stale) == 0))[0]
            ms = (raw_t[i0 + ok[0]] - t0) * 1e3 if len(ok) else math.inf
            row = {"kind": e["kind"], "chip": chip, "t_end": round(e["t_end"], 4), "recovery_ms": round(ms, 1)}
            if overtaken:
                rows.append({**row, "overtaken_by": overtaken})
                continue
            limit = LIMITS["recovery_after_reset_ms" if resetting else "recovery_ms"]
            if not len(ok) and (not len(raw_t) or raw_t[-1] < t0 + limit / 1e3):
                rows.append({**row, "recovery_ms": None, "skipped": "the run ended first"})
                continue  # a fault in the run's last moments: no RAW_SAMPLE after it to judge by
            rows.append(row)
            if ms > limit:
                worst.add(e["t_end"], 0, f"{chip} after {e['kind']} at {e['t_end']:.3f} s: {ms:.1f} ms")
            worst.count = max(worst.count, ms)
    return worst, rows


def _quats(frames):
    t = np.array([f.t_s for f in frames if isinstance(f.packet, Orientation)])
    q = np.array([f.packet.quat_float for f in frames if isinstance(f.packet, Orientation)]).reshape(-1, 4)
    flags = np.array([f.packet.flags for f in frames if isinstance(f.packet, Orientation)], dtype=int)
    return t, q, flags


def _at(t: float, tt: np.ndarray, qq: np.ndarray, gap_s: float = 0.03, near_s: float = 0.1):
    """The orientation at simulated time ``t`` from the ORIENTATIONs on either side (normalised linear
    interpolation of the quaternions, signs aligned) when they are within ``gap_s`` of each other; else the
    first within ``near_s`` after ``t`` (frames lost); None when there is none. Both runs are compared at the
    same instant: their samples are up to a period apart (a reset's boot delay moves one run's phase), and
    in a fast turn (BROAD's reach 800 °/s) 1 ms is 0.8°."""
    i = int(np.searchsorted(tt, t))
    if i < len(tt) and tt[i] == t:
        return qq[i] / np.linalg.norm(qq[i])
    if i == 0 or i >= len(tt) or tt[i] - tt[i - 1] > gap_s:
        return qq[i] / np.linalg.norm(qq[i]) if i < len(tt) and tt[i] - t <= near_s else None
    u = (t - tt[i - 1]) / (tt[i] - tt[i - 1])
    p, q = qq[i - 1], qq[i]
    q = -q if float(np.dot(p, q)) < 0 else q
    r = (1 - u) * p + u * q
    return r / np.linalg.norm(r)


def _angle_deg(p, q) -> float:
    return math.degrees(2 * math.acos(min(1.0, abs(float(np.dot(p, q))))))


def line_fault_windows(log: list[dict], frames: list[Frame]) -> tuple[list, list]:
    """The windows in which a damaged frame is an injected fault, and the host stalls, from the board's log.
    A reset cuts the frame on the wire, and the cut frame is judged when the next delimiter comes: the rebooted
    firmware's first byte, which may wait for the bus (a chip holding SDA after a reset mid-read) and for the host
    to read again. A host stall drops bytes until it ends."""
    good_t = [f.t_s for f in frames if f.ok]
    line = [(e["t"], _first_good_after(good_t, e["t"]) + LINE_WINDOW_S) for e in log if e["kind"] in RESET_KINDS]
    stall_t, host_stalls = None, []
    for e in log:
        if e["kind"] == "host_stall":
            stall_t = e["t"]
        elif e["kind"] == "host_reads" and stall_t is not None:
            line.append((stall_t, e["t"] + LINE_WINDOW_S))
            host_stalls.append((stall_t, e["t"]))
            stall_t = None
    return line, host_stalls


def _first_good_after(good_t: list[float], t: float) -> float:
    """The first of the intact frames' times ``good_t`` (ascending) after ``t`` (``t`` itself when none is)."""
    i = bisect.bisect_right(good_t, t)
    return good_t[i] if i < len(good_t) else t


#: faults that cost the firmware gyroscope samples (a chip list with the ITG-3200), and the sample period
GYRO_GAP_KINDS = ("nack", "glitch_nack", "stall")
SAMPLE_PERIOD_S = 0.005


def _turn(rates: np.ndarray, dt: float):
    """The rotation (quaternion) of the body turning at each of ``rates`` (rad/s, body frame) for ``dt`` in turn."""
    q = (1.0, 0.0, 0.0, 0.0)
    for w in rates:
        a = float(np.linalg.norm(w)) * dt
        if a > 0:
            axis = w / np.linalg.norm(w) * math.sin(a / 2)
            q = quat.mul(q, (math.cos(a / 2), float(axis[0]), float(axis[1]), float(axis[2])))
    return q


def unavoidable_deg(motion: T.Motion, t0: float, t1: float) -> float:
    """What a perfect filter loses across a gap in the gyroscope's samples from ``t0`` to ``t1`` s: the body's
    true turn over it (the motion's rate at its own rate, integrated) against the best the samples on either side
    allow, the rate going linearly from the one at ``t0`` to the one at ``t1`` (the trapezoid the firmware bridges
    with), in degrees. In BROAD's fast turns a 50 ms gap costs up to 12.5 deg this way (the soak's motion); neither
    the accelerometer (a fast turn's linear acceleration: rejected) nor the magnetometer (blind to a turn about
    the field) gives it back within 2 s."""
    r = motion.rate_hz
    i0, i1 = max(0, int(math.floor(t0 * r))), min(len(motion.gyr_rad_s) - 1, int(math.ceil(t1 * r)))
    w = motion.gyr_rad_s[i0 : i1 + 1]
    if len(w) < 3:
        return 0.0
    k = len(w) - 1
    true = _turn((w[:-1] + w[1:]) / 2, 1.0 / r)
    line = w[0] + (w[-1] - w[0]) * ((np.arange(k) + 0.5) / k)[:, None]
    return _angle_deg(true, _turn(line, 1.0 / r))


def orientation_excess(frames: list[Frame], ref: list[Frame], ends: list[dict], resets_t: list[float],
                       host_stalls=(), after_s: float = 2.0,
                       settle_after_reset_s: float = 2.5, motion: T.Motion | None = None) -> tuple[Invariant, list]:
    """orientation_excess_deg: what each fault did to the device's ORIENTATION against the reference run's (the
    same motion and resets, no other faults), ``after_s`` after the fault ends, both runs taken at the same
    instant (:func:`_at`): the angle between them then (``diff_deg``), unless they were already apart before the
    fault started (``before_deg``; the reference has the resets too, and two start-ups can end degrees apart and
    stay so): then only as far as the fault moved the device against the reference (``moved_deg``, the
    earth-frame offset then against the one at the fault's start). ``excess_deg`` = min(diff, moved): a check
    fails when the device is over the limit off the reference and the fault moved it that far.

    Not judged: within ``settle_after_reset_s`` of a reset (the firmware's start-up is not the same to the
    millisecond in both runs), nor while either run says it is still converging (ORIENTATION ``converging``, its
    start-up gain) between the fault's start and the check: two start-ups are compared then, not the fault's
    doing (rows with ``skipped``). A check that falls while the host is not reading is made when it reads again
    (nothing the device sent in between reaches it); a fault that starts while the host is not reading is
    measured from the last ORIENTATION the host got before it. A fault that cost gyroscope samples is judged
    beyond what a perfect filter would have lost across the gap (``unavoidable_deg``, :func:`unavoidable_deg`,
    from the true motion when ``motion`` is given): the limit stays, the physics is not the firmware's doing."""
    ta, qa, fa = _quats(frames)
    tb, qb, fb = _quats(ref)
    worst = Invariant()
    rows = []
    for e in ends:
        if e["kind"] in RESET_KINDS or e["kind"] == "sda_held_at_power_up":
            continue
        t = e["t_end"] + after_s
        t = max([t] + [b + 0.05 for a, b in host_stalls if a <= t <= b + 0.05])
        if not len(ta) or not len(tb) or t > min(ta[-1], tb[-1]):
            continue  # the run ended first
        if any(r - 0.1 <= t <= r + settle_after_reset_s for r in resets_t):
            continue
        row = {"kind": e["kind"], "chips": e["chips"], "t": round(t, 4)}
        # the fault's start, or when it came while the host was not reading, the last ORIENTATION the host got
        # before it (a host stall does nothing to the device's estimate)
        t0 = e.get("t_start", e["t_end"])
        if any(a <= t0 <= b for a, b in host_stalls):
            i = int(np.searchsorted(ta, t0, side="right")) - 1
            t0 = float(ta[i]) if i >= 0 else t0
        conv = [bool(np.any(f[(tt >= t0 - 0.1) & (tt <= t + 0.1)] & ORI_CONVERGING)) for tt, f in ((ta, fa), (tb, fb))]
        if any(conv):
            rows.append({**row, "excess_deg": None, "skipped": "converging ("
                         + " and ".join(n for n, c in zip(("device", "reference"), conv) if c) + ")"})
            continue
        pa, pb = _at(t, ta, qa), _at(t, tb, qb)
        ba, bb = _at(t0, ta, qa), _at(t0, tb, qb)
        deg = _angle_deg(pa, pb) if pa is not None and pb is not None else math.inf  # no orientation then
        row["before_deg"] = row["moved_deg"] = None
        if ba is not None and bb is not None:
            row["before_deg"] = round(_angle_deg(ba, bb), 2)
            if pa is not None and pb is not None:  # how far the fault moved the device against the reference
                moved = _angle_deg(quat.mul(quat.mul(pa, quat.conj(pb)), quat.mul(bb, quat.conj(ba))), (1.0, 0.0, 0.0, 0.0))
                row["moved_deg"] = round(moved, 2)
                row["diff_deg"] = round(deg, 2)
                deg = min(deg, moved)
        if motion is not None and e["kind"] in GYRO_GAP_KINDS and "itg3200" in e["chips"] and math.isfinite(deg):
            # what no filter could have avoided: the turn across the gap (from the last fresh sample, up to a
            # period before the fault, to the first after it); only the rest is the firmware's
            u = unavoidable_deg(motion, e["t_start"] - SAMPLE_PERIOD_S, e["t_end"] + SAMPLE_PERIOD_S)
            row["unavoidable_deg"] = round(u, 2)
            deg = max(0.0, deg - u)
        row["excess_deg"] = round(deg, 2)
        rows.append(row)
        if deg > LIMITS["orientation_excess_deg"]:
            worst.add(t, 0, f"{deg:.1f} deg {after_s:g} s after {e['kind']} ({','.join(e['chips'])}) ended")
        worst.count = max(worst.count, deg)
    return worst, rows


def fault_free_checks(frames: list[Frame], ref: list[Frame], log: list[dict], resets_t: list[float], host_stalls=(),
                      step_s: float = 0.25, after_s: float = 2.0) -> dict:
    """The orientation check made where nothing was injected: from every ``step_s`` instant with nothing in the
    board's fault log (glitches, host stalls and resets too) from 0.5 s before it to its check ``after_s`` later,
    by the rules of :func:`orientation_excess`. What it finds is the difference two runs of the same firmware show
    with no fault to blame: the check's own noise, reported beside the faults' (not judged)."""
    t = np.array([f.t_s for f in frames if isinstance(f.packet, Orientation)])
    logged = sorted(e["t"] for e in log)
    ends = []
    for t0 in np.arange(LEAD_IN_S, (t[-1] - after_s) if len(t) else 0.0, step_s):
        t0 = float(t0)
        i = bisect.bisect_left(logged, t0 - 0.5)
        if i < len(logged) and logged[i] <= t0 + after_s + 0.1:
            continue
        if any(a - 0.5 <= t0 + after_s + 0.1 and t0 - 0.5 <= b for a, b in host_stalls):
            continue
        ends.append({"kind": "none", "t_start": t0, "t_end": t0, "chips": []})
    _, rows = orientation_excess(frames, ref, ends, resets_t, host_stalls, after_s=after_s)
    judged = [(r["excess_deg"], r["t"]) for r in rows if r.get("excess_deg") is not None]
    v = np.array([x for x, _ in judged if math.isfinite(x)])
    worst = max(judged) if judged else (None, None)
    return {"windows": len(v), "p95_deg": round(float(np.percentile(v, 95)), 2) if len(v) else None,
            "max_deg": worst[0], "max_t": worst[1],
            "over_limit": int(np.sum(v > LIMITS["orientation_excess_deg"])) if len(v) else 0}


def start_ups(frames: list[Frame], resets_t) -> list[dict]:
    """How long the firmware says it is converging after power-up and after each reset: from the reset to its
    first ORIENTATION without ``converging`` ({t, seconds}; seconds None when the next reset or the run's end
    came first; one that ends while the host is not reading counts to the first ORIENTATION it gets). Reported
    beside the orientation checks, which skip a start-up, so that a start-up that never ends shows."""
    t, _, flags = _quats(frames)
    out = []
    starts = [0.0] + sorted(resets_t)
    for k, r in enumerate(starts):
        nxt = starts[k + 1] if k + 1 < len(starts) else math.inf
        sel = np.flatnonzero((t > r) & (t < nxt) & ((flags & ORI_CONVERGING) == 0))
        out.append({"t": round(r, 4), "seconds": round(float(t[sel[0]] - r), 3) if len(sel) else None})
    return out


# ---------------------------------------------------------------- the run


def soak_motion(seconds: float, chunk_s: float = 20.0):
    """BROAD motion for ``seconds``: a still lead-in, then ``chunk_s`` slices of the trials in turn, each
    from 2 s before its first movement."""
    paths = trial_paths()
    if not paths:
        raise FileNotFoundError("no BROAD trials found (SPHERE_BROAD_DIR)")
    parts, total, i = [], LEAD_IN_S, 0
    while total < seconds:
        tr = load_trial(paths[i % len(paths)])
        first = int(np.argmax(tr.movement)) / tr.rate_hz if tr.movement.any() else 0.0
        start = max(0.0, first - 2.0)
        sl = tr.seconds(start, min(chunk_s, len(tr) / tr.rate_hz - start, seconds - total + 1.0))
        m = T.from_broad(sl)
        if parts and abs(m.rate_hz - parts[0].rate_hz) > 1e-6:
            m = T.Motion(parts[0].rate_hz, *(T.resample(x, m.rate_hz, parts[0].rate_hz)
                                              for x in (m.acc_m_s2, m.gyr_rad_s, m.mag_uT)), m.name)
        parts.append(m)
        total += m.seconds
        i += 1
    cat = T.Motion(parts[0].rate_hz, *(np.concatenate([getattr(p, k) for p in parts])
                                       for k in ("acc_m_s2", "gyr_rad_s", "mag_uT")), "soak")
    return T.hold_first(cat, LEAD_IN_S), [p.name for p in parts]


def schedule(seconds: float, seed: int, kinds=FAULT_KINDS, mag: str = "hmc5883l") -> dict:
    """A seeded schedule of faults as run_board keywords: one fault every 4-7 s from 6 s on, each of a
    random kind; a low rate of random glitches all through; a sensor holding SDA at power-up."""
    rng = np.random.default_rng(seed)
    kw = {"nack": [], "stall": [], "brownout": [], "reset_mid_read": [], "host_stall": []}
    spaced = [k for k in kinds if k in ("nack", "stall", "brownout", "reset_mid_read", "host_stall")]
    t, order, chips = 6.0, [], []
    while spaced and t < seconds - 3.0:
        if not order:  # every kind once in a random order, then again: a short soak still has each
            order = [spaced[i] for i in rng.permutation(len(spaced))]
        k = order.pop()
        if k == "nack":
            if not chips:
                chips = [("adxl345", "itg3200", "hmc5883l")[i] for i in rng.permutation(3)]
            chip = chips.pop()
            d = float(rng.uniform(0.005, 0.05 if chip != "hmc5883l" else 0.2))
            kw["nack"].append(f"{chip}:{t:.4f}:{t + d:.4f}")
        elif k == "stall":
            kw["stall"].append(f"{t:.4f}:{t + float(rng.uniform(0.002, 0.02)):.4f}")
        elif k == "host_stall":
            kw["host_stall"].append(f"{t:.4f}:{t + float(rng.uniform(0.2, 1.5)):.4f}")
        else:
            kw[k].append(round(t, 4))
        t += float(rng.uniform(4.0, 7.0))
    if "glitch" in kinds:
        kw["glitch"] = 0.2
    kw["sda_held"] = "sda_held" in kinds
    return {k: v for k, v in kw.items() if v}


def board_profile_command(board: str | None, path: Path) -> Path | None:
    """A SET_BOARD command for the firmware at 0.5 s when the board is not the aligned one (as its owner
    would send once; the firmware keeps it in EEPROM), so the firmware maps the chips as they are mounted.
    None when the board is the aligned one or the host's protocol has no SET_BOARD."""
    if not board or board == "aligned" or not hasattr(packets, "SetBoard"):
        return None
    number = {name: n for n, name in packets.BOARD_PROFILES.items()}.get(board.split("-")[0])
    if number is None:
        return None

    path.write_text(f"0.5 {encode_frame(packets.SetBoard(board_profile=number), 0).hex(' ')}\n")
    return path


def reference_resets(log: list[dict]) -> dict:
    """run_board keywords for the reference: the faulty run's resets, each as it came, so that both runs start
    their firmware at the same cycle and read the chips at the same phase of the chips' own sample clocks.

    A reset in the middle of a read (scheduled, or one of the glitches) is asked again 1 ms before it came: the
    board asks at its 1 ms checks and resets at the next byte a chip sends, which is that same byte; the chip
    then holds SDA as it did. The sensor holding SDA at power-up holds it in both. A reference reset plainly, or
    without the held SDA, booted up to 0.3 s apart from the faulty run: with the chips' clocks off the Nano's
    (--clocks random) the firmware then reads a gyro sample twice, or misses one, at other instants than the
    faulty run does, and in BROAD's fast turns the two runs drifted up to 3.8 degrees apart within 2 s with no
    fault at all."""
    kw = {"brownout": [e["t"] for e in log if e["kind"] == "brownout"],
          "reset_mid_read": [round(e["t"] - 0.001, 6) for e in log if e["kind"] == "reset_mid_read"],
          "sda_held": any(e["kind"] == "sda_held_at_power_up" for e in log)}
    return {k: v for k, v in kw.items() if v}


@dataclass
class SoakResult:
    report: dict
    failed: list = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.failed

    def summary_line(self) -> str:
        r = self.report
        inv = r["invariants"]

        def f(k, unit=""):
            v = inv[k]
            first = f" first {v['first_s']:.2f} s" if v.get("first_s") is not None else ""
            c = v["count"]
            c = "never" if c is None or c == math.inf else (f"{c:.1f}" if isinstance(c, float) and not float(c).is_integer() else int(c))
            return f"{k} {c}{unit}{first}"
        return (f"sphere sim --soak {r['seconds']:g} s seed {r['seed']} board {r['board']}: "
                + ", ".join([f("stale_frames"), f("crc_errors"), f("sensor_recovery_ms"),
                             f("orientation_excess_deg") + (f" ({inv['orientation_excess_deg']['checks']} checks, "
                                                            f"{inv['orientation_excess_deg']['skipped_converging']} in a "
                                                            "start-up)" if "checks" in inv["orientation_excess_deg"] else ""),
                             f"resets {inv['resets']['count']} ({inv['resets']['injected']} injected)",
                             *([f"start-up longest {inv['start_up_s']['longest']:.2f} s"]
                               if inv.get("start_up_s", {}).get("longest") is not None else []),
                             f"overruns {inv['overruns']['count']}", f("frames_dropped")])
                + (" -> FAIL: " + ", ".join(self.failed) if self.failed else " -> PASS")
                + f" [x{r['speed']:.2f} real time per CPU core]")


def run_soak(elf, seconds: float, seed: int, board: str | None = None, kinds=FAULT_KINDS,
             tmp: Path | None = None, build: bool = True, keep: Path | None = None) -> SoakResult:
    """Run the faulty and the fault-free board on the same motion; check the invariants."""
    with tempfile.TemporaryDirectory(prefix="sphere-soak-") as tmpd:
        tmp = Path(tmpd)
        motion, trials = soak_motion(seconds)
        trace = T.to_chips(motion).write(tmp / "trace.bin")
        common = dict(board=board, noise=True, seed=seed, clocks_random=True, build=build)
        send = board_profile_command(board, tmp / "send.txt")
        if send:
            common["send"] = send
        faults = schedule(seconds, seed, kinds)

        def one(name, kw):
            cap, times = tmp / f"{name}.cap", tmp / f"{name}.times"
            r = run_board(elf, trace, seconds, cap, capture_times=times, **common, **kw)
            return r, cap.read_bytes() if cap.exists() else b"", times.read_bytes() if times.exists() else b""

        # the reference: the same motion, chips and clocks without the faults, but with the faulty run's
        # resets as they came (the firmware starts again in both), so what differs is the faults' doing
        ra, capa, ta = one("faulty", faults)
        log = ra.stats.get("faults", [])
        ref_kw = reference_resets(log)
        rb, capb, tb = one("reference", ref_kw)
        if keep:
            keep.mkdir(parents=True, exist_ok=True)
            for name in ("faulty.cap", "faulty.times", "reference.cap", "reference.times", "trace.bin"):
                if (tmp / name).exists():
                    (keep / name).write_bytes((tmp / name).read_bytes())
    for r in (ra, rb):
        if r.returncode != 0:
            raise RuntimeError(f"the board exited with {r.returncode}: {r.stderr.strip()[-500:]}")
    frames, ref = read_frames(capa, ta), read_frames(capb, tb)
    mag = ra.stats.get("magnetometer", "hmc5883l")
    chips = ["adxl345", "itg3200", mag]
    for e in log:
        if e.get("chip") == "hmc5883l":
            e["chip"] = mag
    ends = fault_ends(log, chips)
    resets_t = [e["t"] for e in log if e["kind"] in RESET_KINDS]
    line, host_stalls = line_fault_windows(log, frames)
    s = stream_checks(frames, line, resets_t)
    rec, rec_rows = recovery(frames, ends, host_stalls)
    ori, ori_rows = orientation_excess(frames, ref, ends, resets_t, host_stalls, motion=motion)
    ups = start_ups(frames, resets_t)
    ended = [u["seconds"] for u in ups if u["seconds"] is not None]
    resets = max(0, s["hellos"] + s["hellos_lost"] - 1)
    injected = len(resets_t)
    inv = {
        "stale_frames": s["stale_frames"].as_dict(),
        "crc_errors": s["crc_errors"].as_dict(),
        "sensor_recovery_ms": rec.as_dict(),
        "orientation_excess_deg": {**ori.as_dict(), "checks": sum(1 for r in ori_rows if "skipped" not in r),
                                   "skipped_converging": sum(1 for r in ori_rows if "skipped" in r)},
        "resets": {"count": resets, "injected": injected},
        "overruns": {"count": s["overruns"], "timing_pin": ra.stats.get("overruns")},
        "frames_dropped": s["frames_dropped"].as_dict(),
        "start_up_s": {"longest": max(ended) if ended else None, "median": float(np.median(ended)) if ended else None,
                       "unfinished": sum(1 for u in ups if u["seconds"] is None), "count": len(ups)},
        "orientation_without_fault_deg": fault_free_checks(frames, ref, log, resets_t, host_stalls),
    }
    failed = [k for k in ("stale_frames", "crc_errors") if inv[k]["count"] > 0]
    if rec.first_s is not None or not rec_rows and ends:
        failed.append("sensor_recovery_ms")
    if ori.first_s is not None:
        failed.append("orientation_excess_deg")
    if resets > injected:  # a reset nobody injected (a watchdog); one during start-up may send no HELLO
        failed.append("resets")
    speed = [r.stats.get("speed_cpu") or r.stats.get("speed", 0) for r in (ra, rb)]
    report = {
        "seconds": seconds, "seed": seed, "board": ra.stats.get("board"), "magnetometer": mag,
        "firmware": str(elf), "trials": trials, "limits": LIMITS, "invariants": inv,
        "faults_scheduled": faults, "faults": log, "recoveries": rec_rows, "orientation_checks": ori_rows, "start_ups": ups,
        "board_stats": {k: ra.stats.get(k) for k in ("clock_ppm", "glitches", "i2c_errors", "host_dropped_bytes",
                                                     "hmc5883l_measurements", "hmc5883l_held_by_lock")},
        "speed": min(speed) if speed else 0.0, "failed": failed,
    }
    return SoakResult(json.loads(json.dumps(report, default=float).replace("Infinity", "null")), failed)
