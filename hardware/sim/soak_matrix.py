#!/usr/bin/env python3
"""The soak (`sphere sim --soak`) on a matrix of seeds × board variants, as issue 31's target asks: every run
passes, on seeds nobody designed on, on every board. Prints one line per run as it ends, then a table (a row
per seed, a column per board: PASS or what failed, with the largest orientation excess after a fault) and the
count of runs that passed; exit 1 when any failed.

    python hardware/sim/soak_matrix.py --seeds 201-220 [--board NAME ...] [--seconds 120] [--jobs 2]
        [--json OUT.json] [--keep DIR]

--seeds takes a range A-B and/or a list (201-205,230). Each run is `sphere sim --soak SECONDS --seed N --board
B` (the faulty and the fault-free board one after the other, about 20-40 CPU s for 120 s); --jobs runs that
many at once. --json writes every run's report (as each run ends); --keep DIR keeps each run's captures and trace under
DIR/SEED-BOARD/ for a closer look. Part of the MARG sphere's virtual board (hardware/sim); GPL-3.0-or-later.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path


def seed_list(text: str) -> list[int]:
    """'201-220', '5,9,12' or both ('1-3,7') as a list of seeds in the order given, each once."""
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        a, sep, b = part.partition("-")
        try:
            lo, hi = int(a), int(b) if sep else int(a)
        except ValueError:
            raise argparse.ArgumentTypeError(f"seeds are numbers or ranges A-B, not {part!r}") from None
        if lo < 0 or hi < lo:
            raise argparse.ArgumentTypeError(f"a seed range goes up from 0 or more, not {part!r}")
        out += [s for s in range(lo, hi + 1) if s not in out]
    if not out:
        raise argparse.ArgumentTypeError("no seeds given")
    return out


def cell(report: dict | None, error: str | None = None) -> str:
    """A table cell: PASS or FAIL with what failed, and the largest orientation excess after a fault."""
    if report is None:
        return f"ERROR {error}"
    inv = report["invariants"]
    ori = inv["orientation_excess_deg"]["count"]
    ori_s = "-" if ori is None else f"{ori:.1f}°"
    if not report["failed"]:
        return f"PASS {ori_s}"
    what = []
    for k in report["failed"]:
        v = inv.get(k, {})
        first = v.get("first_s") if isinstance(v, dict) else None
        what.append(k + (f" @{first:.2f} s" if first is not None else ""))
    return f"FAIL {ori_s} " + ", ".join(what)


def write_json(path: str, runs: list, results: dict) -> None:
    Path(path).write_text(json.dumps([{"seed": s, "board": b, "report": results[(s, b)]} for s, b in runs
                                      if (s, b) in results], indent=1) + "\n")


def main(argv=None) -> int:
    from sphere.sim.board import BOARD_VARIANTS, firmware_elf
    from sphere.sim.soak import run_soak

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=seed_list, required=True, metavar="A-B,...")
    p.add_argument("--board", action="append", choices=BOARD_VARIANTS, default=None,
                   help="a board variant (repeatable; default all)")
    p.add_argument("--seconds", type=float, default=120.0)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--firmware", default=None)
    p.add_argument("--json", default=None, metavar="OUT.json")
    p.add_argument("--keep", default=None, metavar="DIR")
    a = p.parse_args(argv)
    if a.jobs < 1 or a.seconds < 10:
        p.error("--jobs must be at least 1 and --seconds at least 10 (faults start at 6 s)")
    boards = a.board or list(BOARD_VARIANTS)
    runs = [(s, b) for s in a.seeds for b in boards]
    results: dict[tuple[int, str], dict | str] = {}
    with tempfile.TemporaryDirectory(prefix="soak-matrix-") as tmpd:
        src = Path(a.firmware) if a.firmware else firmware_elf()
        elf = Path(tmpd) / src.name  # a rebuild of the firmware meanwhile must not change the image under test
        shutil.copyfile(src, elf)

        def one(sb):
            seed, board = sb
            keep = Path(a.keep) / f"{seed}-{board}" if a.keep else None
            try:
                res = run_soak(elf, a.seconds, seed, board=board, keep=keep)
                out = res.report
                line = res.summary_line()
            except (FileNotFoundError, RuntimeError) as e:
                out, line = str(e), f"seed {seed} board {board}: ERROR {e}"
            print(line, flush=True)
            return sb, out

        with ThreadPoolExecutor(max_workers=a.jobs) as ex:
            for sb, out in ex.map(one, runs):
                results[sb] = out
                if a.json:  # rewritten as runs end: an interrupted matrix keeps what it did
                    write_json(a.json, runs, results)
    print(f"\nsphere sim --soak {a.seconds:g} --seed N --board B, firmware {src}")
    print("| seed | " + " | ".join(boards) + " |")
    print("|---|" + "---|" * len(boards))
    passed = 0
    for s in a.seeds:
        cells = []
        for b in boards:
            r = results[(s, b)]
            cells.append(cell(r) if isinstance(r, dict) else cell(None, r))
            passed += isinstance(r, dict) and not r["failed"]
        print(f"| {s} | " + " | ".join(cells) + " |")
    print(f"{passed} of {len(runs)} passed (seeds {','.join(map(str, a.seeds))}; boards {', '.join(boards)})")
    return 0 if passed == len(runs) else 1


if __name__ == "__main__":
    sys.exit(main())
