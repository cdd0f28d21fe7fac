#!/usr/bin/env python3
"""Choose the firmware's β and input gates (marg_filter.h, input_gates.cpp) by leave-one-trial-out.

Every shipped BROAD trial is cut as `sphere sim --trace all --accuracy --hold 2 --seconds 60` cuts it
(from 10 s before its first movement, after a 2 s still lead-in), turned into the chips' samples
(sphere.sim.trace; the gyroscope through the ITG-3200's 98 Hz DLPF at its 1 kHz internal rate and read
0.5 ms after its output register was refreshed (SMPLRT_DIV 0: a new value every 1 ms), the accelerometer 1.25 ms after, as on the board) and replayed through the real SphereDevice natively (firmware/build/device_replay:
power-up bias, bias tracking, gates, start-up gain, fixed-point Madgwick). Its ORIENTATION stream
(100 Hz) is scored with the dataset's metric (sphere.broad.orientation_error) for each setting of a grid.

Leave-one-trial-out: for each trial, the setting with the lowest mean total error over the OTHER trials
is chosen and scored on the trial left out; the mean of those held-out scores is what the gates are
worth on a trial they were not chosen on. The setting written into the firmware is the one chosen on
all trials, and it is printed with how many folds chose it.

    make -C firmware tune            (or: python3 firmware/bench/tune_gates.py --replay firmware/build/device_replay)
"""

from __future__ import annotations

import argparse
import itertools
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from scipy.signal import butter, lfilter

from sphere import broad, chips
from sphere import quaternion as quat
from sphere.sim import trace as T

HOLD_S, SECONDS = 2.0, 60.0
TICK_S = 0.005
# β (1/1000), accel_tol_lsb (256 = 1 g), mag_norm_tol_q8 (/256), mag_dip_tol_q14 (sin dip), learn_shift,
# relearn_after (samples), hold (samples a rejection outlasts its cause; InputGates' option, 0 = none).
# β stays Madgwick's 0.041 (MARG_FILTER.md: a lower β was better on the replay, 0.020: 2.99° held out,
# but it is the protocol's documented default and the soak's recovery after a fault is slower with it)
GRID = {
    "beta_milli": (41,),
    "accel_tol_lsb": (26, 51),
    "mag_norm_tol_q8": (51, 255),
    "mag_dip_tol_q14": (3277, 32767),
    "learn_shift": (9,),
    "relearn_after": (2000,),
    "hold": (0,),
}
ITG_INTERNAL_HZ, ITG_DLPF_HZ = 1000.0, 98.0  # DLPF_CFG 2 (ITG-3200 datasheet §8.3, register 22)
GYRO_AGE_S, ACCEL_AGE_S = 0.0005, 0.00125      # mean age of the output register when read (1 ms, 2.5 ms periods)


def replay_input(trial, path: Path):
    """The trial slice as the board plays it, sampled at the firmware's 5 ms ticks; returns the slice."""
    first = int(np.argmax(trial.movement)) / trial.rate_hz if trial.movement.any() else 0.0
    start = max(0.0, first - 10.0)
    total = len(trial) / trial.rate_hz
    sl = trial.seconds(start, min(SECONDS - HOLD_S, total - start))
    m = T.hold_first(T.from_broad(sl), HOLD_S)
    ct = T.to_chips(m)
    n = len(ct.accel_lsb)
    t = np.arange(n) * TICK_S
    mi = np.minimum((t * ct.mag_rate_hz).astype(int), len(ct.mag_lsb) - 1)
    # the gyroscope as the chip delivers it: a 2nd-order Butterworth at the DLPF bandwidth (as the
    # simulated chip, hardware/sim/sensors.c), sampled at 1 kHz, GYRO_AGE_S old when read
    g1k = T.resample(T.fill_gaps(m.gyr_rad_s), m.rate_hz, ITG_INTERNAL_HZ)
    b, a = butter(2, ITG_DLPF_HZ, fs=ITG_INTERNAL_HZ)
    g = chips.gyro_rad_s_to_lsb(np.stack([lfilter(b, a, g1k[:, i]) for i in range(3)], axis=1))
    gi = np.clip(((t - GYRO_AGE_S) * ITG_INTERNAL_HZ).astype(int), 0, len(g) - 1)
    ai = np.clip(((t - ACCEL_AGE_S) * ct.accel_rate_hz).astype(int), 0, len(ct.accel_lsb) - 1)
    rec = np.hstack([ct.accel_lsb[ai], g[gi], ct.mag_lsb[mi]]).astype("<i2")
    path.write_bytes(b"SPHREPLY" + struct.pack("<I", n) + rec.tobytes())
    return sl, n


def score(replay: str, inp: Path, n: int, sl, setting) -> float:
    out = inp.with_suffix(".out")
    args = [replay, str(inp), str(out)] + ([str(v) for v in setting] if setting else [])
    subprocess.run(args, check=True)
    o = np.frombuffer(out.read_bytes(), dtype="<i2").reshape(n, 5)
    ticks = np.arange(0, n, 2)  # ORIENTATION at 100 Hz: every second period, from the first
    t_o = ticks * TICK_S
    q_o = o[ticks, 1:].astype(float) / 16384.0
    t_trial = HOLD_S + np.arange(len(sl)) / sl.rate_hz
    idx = np.clip(np.searchsorted(t_o, t_trial, side="right") - 1, 0, len(t_o) - 1)
    q = quat.nwu_to_enu(quat.normalize(q_o[idx]))
    return broad.orientation_error(q, sl).total


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--replay", default="firmware/build/device_replay")
    ap.add_argument("--inputs", type=Path, help="only write each trial's replay input (DIR/NAME.bin) and stop")
    args = ap.parse_args()
    trials = [broad.load_trial(p) for p in broad.trial_paths()]
    if args.inputs:
        args.inputs.mkdir(parents=True, exist_ok=True)
        for t in trials:
            replay_input(t, args.inputs / f"{t.name}.bin")
        print(f"{len(trials)} replay inputs in {args.inputs}")
        return 0
    names = [t.name for t in trials]
    settings = list(itertools.product(*GRID.values()))
    with tempfile.TemporaryDirectory() as tmp:
        inputs = []
        for t in trials:
            p = Path(tmp) / f"{t.name}.bin"
            sl, n = replay_input(t, p)
            inputs.append((p, n, sl))
        base = [score(args.replay, p, n, sl, None) for p, n, sl in inputs]
        table = np.array([[score(args.replay, p, n, sl, s) for p, n, sl in inputs] for s in settings])
    print(f"{len(settings)} settings x {len(trials)} trials; firmware defaults: mean total {np.mean(base):.2f} deg")
    held_out, chosen = [], []
    for k in range(len(trials)):
        others = np.delete(table, k, axis=1).mean(axis=1)
        best = int(np.argmin(others))
        chosen.append(best)
        held_out.append(table[best, k])
        print(f"  left out {names[k]:44s} chosen {settings[best]}  held-out {table[best, k]:.2f} deg "
              f"(defaults {base[k]:.2f})")
    print(f"leave-one-trial-out mean total: {np.mean(held_out):.2f} deg (firmware defaults {np.mean(base):.2f})")
    best_all = int(np.argmin(table.mean(axis=1)))
    print(f"chosen on all trials: {dict(zip(GRID, settings[best_all]))}, mean {table[best_all].mean():.2f} deg; "
          f"chosen by {chosen.count(best_all)} of {len(trials)} folds")
    return 0


if __name__ == "__main__":
    sys.exit(main())
