#!/usr/bin/env python3
"""The firmware's restarts behind each of the Nano's boot loaders (issue 32's targets), on the virtual board:
REBOOT, a hung main loop (0.3 s: the watchdog's restart) and a host's DTR reset, COUNT times each in a row,
with the chips' noise. For each: how many HELLOs came within 2 s, the slowest, the reset causes HELLO gave
(right: the event's flag, or 0 = unknown), how many were wrong, and in how many the gyro bias was kept.

    python hardware/sim/bench_restarts.py [--count 100] [--bootloader NAME ...] [--kind KIND ...] [--jobs 2]

Targets: every event HELLO again within 2 s; no wrong cause; the kept bias kept after a DTR reset on each.
Part of the MARG sphere's virtual board (hardware/sim); GPL-3.0-or-later like the board.
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path


def main(argv=None) -> int:
    from sphere.sim.board import BOOTLOADERS, firmware_elf
    from sphere.sim.restarts import KINDS, restart_run

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--count", type=int, default=100)
    p.add_argument("--bootloader", action="append", choices=BOOTLOADERS, default=None)
    p.add_argument("--kind", action="append", choices=KINDS, default=None)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--firmware", default=None)
    p.add_argument("--seed", type=int, default=1)
    a = p.parse_args(argv)
    if a.count < 1 or a.jobs < 1:
        p.error("--count and --jobs must be at least 1")
    elf = Path(a.firmware) if a.firmware else firmware_elf()
    runs = [(b, k) for b in (a.bootloader or BOOTLOADERS) for k in (a.kind or KINDS)]
    with ThreadPoolExecutor(max_workers=a.jobs) as ex:
        results = list(ex.map(lambda bk: restart_run(elf, bk[0], bk[1], a.count, seed=a.seed), runs))
    print(f"{a.count} events each, firmware {elf}")
    print("| boot loader | event | HELLO within 2 s | slowest s | reset causes | wrong | bias kept | board resets |")
    print("|---|---|---|---|---|---|---|---|")
    fail = False
    for r in results:
        causes = ", ".join(f"0x{c:02x}" for c in r["causes"]) or "-"
        print(f"| {r['bootloader']} | {r['kind']} | {r['within_2s']}/{r['count']} | {r['max_latency_s']} | {causes} | "
              f"{r['wrong_cause']} | {r['bias_kept']}/{r['count']} | {r['board_resets']} |")
        fail |= r["within_2s"] < r["count"] or r["wrong_cause"] > 0 or r["bias_kept"] < r["count"]
    print("PASS" if not fail else "FAIL")
    return 1 if fail else 0


if __name__ == "__main__":
    sys.exit(main())
