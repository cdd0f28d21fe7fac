#!/usr/bin/env python3
"""Issue 32's storage, reflash and bus targets on the virtual board, for a firmware image and optionally an older
one side by side (--against): SAVE_CALIBRATION while turning at 200 deg/s (missed periods, degrees from the run
without it, when the REPLY came), a reflash over a stick an earlier sketch left in FIFO stream mode with an offset
(the age of the first accelerometer read), and the bus (the AVR's pull-ups, a line driven high, the SCL low time).

    python hardware/sim/bench_nano.py [--firmware PATH.elf] [--against OLD.elf]

Targets: 0 missed periods and < 1 deg; first read < 5 ms old; no pull-up, nothing driven high, SCL low >= 1.3 us.
(REBOOT, hangs and DTR resets behind each boot loader: bench_restarts.py.)
Part of the MARG sphere's virtual board (hardware/sim); GPL-3.0-or-later like the board.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from sphere.sim import trace as T
from sphere.sim.board import firmware_elf, probe_elf, run_board
from sphere.sim.storage import save_while_turning

# what the earlier sketch leaves: 400 Hz, stream mode (watermark 31), OFSX 5 (78 mg), measuring
EARLIER_SKETCH = [(0.3, "w 53 2c 0c"), (0.35, "w 53 38 9f"), (0.4, "w 53 1e 05"), (0.45, "w 53 2d 08")]


def reflash_and_bus(elf) -> dict:
    with tempfile.TemporaryDirectory(prefix="sphere-nano-") as tmp:
        tmp = Path(tmp)
        trace = T.to_chips(T.still(2.0)).write(tmp / "t.bin")
        (tmp / "s.txt").write_text("".join(f"{t:.3f} {(c + chr(10)).encode().hex(' ')}\n" for t, c in EARLIER_SKETCH))
        r = run_board(elf, trace, 2.0, send=tmp / "s.txt", previous=(probe_elf(), 1.0))
        bus = run_board(elf, trace, 1.0, sda_held=True).stats["bus"]
    return {"first_read_age_ms": r.stats["adxl345_data_age_ms"]["first_after_start"][0],
            "max_read_age_ms": r.stats["adxl345_data_age_ms"]["max"], "bus": bus}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--firmware", default=None)
    p.add_argument("--against", default=None, help="an older image to measure beside it")
    a = p.parse_args(argv)
    images = [("firmware", Path(a.firmware) if a.firmware else firmware_elf())]
    if a.against:
        images.append(("against", Path(a.against)))
    rows = []
    for name, elf in images:
        s = save_while_turning(elf, dps=200)
        rb = reflash_and_bus(elf)
        rows.append((name, elf, s, rb))
    print("| image | missed periods | deg from the run without the save | REPLY after s | first read after the "
          "reflash, ms old | AVR pull-up events | driven high | SCL kHz | SCL low us |")
    print("|---|---|---|---|---|---|---|---|---|")
    ok = True
    for name, elf, s, rb in rows:
        b = rb["bus"]
        print(f"| {name} ({elf.name}) | {s['missed_periods']} | {s['max_diff_deg']:.2g} | {s['reply_after_s']} | "
              f"{rb['first_read_age_ms']:.1f} | {b['avr_pullup_events']} | {b['driven_high_events']} | {b['scl_khz']} | "
              f"{b['scl_low_us']} |")
        if name == "firmware":
            ok = (s["missed_periods"] == 0 and s["max_diff_deg"] < 1.0 and rb["first_read_age_ms"] < 5.0
                  and b["avr_pullup_events"] == 0 and b["driven_high_events"] == 0 and b["scl_low_ok"])
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
