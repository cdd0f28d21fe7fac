#!/usr/bin/env python3
"""How fast the virtual board runs the firmware: simulated seconds per second of the board process's own
CPU time (what one core gives, whatever else the machine runs) and per wall second, at the real 400 kHz
I2C timing (the default) beside simavr's own 1 us steps, on a BROAD trial.

    python hardware/sim/bench_speed.py [--seconds 30] [--trial 24] [--firmware PATH.elf] [--noise]

Target (issue 11): at least 2x real time on one core at the real I2C timing.
Part of the MARG sphere's virtual board (hardware/sim); GPL-3.0-or-later like the board.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=30.0)
    p.add_argument("--trial", default="24")
    p.add_argument("--firmware", default=None)
    p.add_argument("--noise", action="store_true", help="with the chips' noise and random clocks (the soak's board)")
    a = p.parse_args(argv)
    from sphere.broad import find_trial, load_trial
    from sphere.sim import trace as T
    from sphere.sim.board import firmware_elf, run_board

    elf = Path(a.firmware) if a.firmware else firmware_elf()
    tr = load_trial(find_trial(a.trial))
    with tempfile.TemporaryDirectory(prefix="sphere-speed-") as tmp:
        trace = T.to_chips(T.hold_first(T.from_broad(tr.seconds(0.0, a.seconds)), 2.0)).write(Path(tmp) / "t.bin")
        rows = []
        for name, real in (("real 400 kHz I2C (default)", True), ("simavr 1 us I2C steps", False)):
            r = run_board(elf, trace, a.seconds, i2c_real_timing=real, noise=a.noise, clocks_random=a.noise)
            if r.returncode:
                print(r.stderr, file=sys.stderr)
                return 1
            s = r.stats
            rows.append((name, s["simulated_seconds"], s["cpu_seconds"], s["wall_seconds"]))
    print(f"sphere-board on {elf.name}, trial {a.trial}, {a.seconds:g} simulated s{' (noise, random clocks)' if a.noise else ''}")
    print("| I2C timing | simulated s | CPU s | x real time per CPU core | wall s | x real time (wall) |")
    print("|---|---|---|---|---|---|")
    for name, sim, cpu, wall in rows:
        print(f"| {name} | {sim:.1f} | {cpu:.2f} | {sim / cpu:.2f} | {wall:.2f} | {sim / wall:.2f} |")
    print(f"real / simavr timing, CPU: {rows[0][2] / rows[1][2]:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
