"""The firmware's restarts behind each of the Nano's boot loaders, on the virtual board (hardware/sim/README.md,
"Boot loaders"): REBOOT, a hung main loop (the watchdog's restart) and a host's DTR reset, each repeated, and for
each the HELLO that follows it: how soon, with which `reset_cause`, and whether the gyro bias was kept.

    from sphere.sim.restarts import restart_run
    r = restart_run(firmware_elf(), "atmegaboot", "reboot", count=100)
    r["within_2s"], r["wrong_cause"]

A reset cause is right when it is the event's flag (REBOOT and the watchdog's restart: `watchdog`; DTR:
`external`) or 0, unknown (a boot loader cleared MCUSR); anything else is wrong.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from sphere.protocol import Reboot, encode_frame
from sphere.protocol.packets import REBOOT_MAGIC, Hello
from sphere.sim import trace as T
from sphere.sim.board import run_board
from sphere.sim.soak import read_frames

KINDS = ("reboot", "hang", "dtr")
EXPECTED_CAUSE = {"reboot": 0x08, "hang": 0x08, "dtr": 0x02}
GYRO_BIAS_VALID = 0x01
LEAD_S = 3.0  # still from power-up: behind the old bootloader (1.3 s) the start-up bias estimate (1 s) is done
# between events: a REBOOT's HELLO comes after 0.25 s, a hang's after 0.5 s; a DTR reset behind a boot loader
# takes up to 1.65 s (Optiboot waits 1 s for a programmer), and a HELLO later than 2 s must not be missed
SPACING_S = {"reboot": 1.0, "hang": 1.0, "dtr": 2.05}
HANG_S = 0.3  # each hang: longer than the watchdog's 0.25 s


def event_times(kind: str, count: int) -> list[float]:
    return [LEAD_S + i * SPACING_S[kind] for i in range(count)]


def restart_run(elf, bootloader: str, kind: str, count: int, seed: int = 1, board_kw=None) -> dict:
    """Run ``count`` events of ``kind`` on the board behind ``bootloader``; returns the figures per event and in
    sum: ``latency_s`` (event to the next HELLO, None when none came before the next event), ``causes``,
    ``bias_kept`` (HELLO's calibration_state has gyro_bias_valid at once), ``within_2s``, ``wrong_cause``."""
    if kind not in KINDS:
        raise ValueError(f"kind {kind!r}: one of {', '.join(KINDS)}")
    times = event_times(kind, count)
    seconds = times[-1] + SPACING_S[kind]
    kw = dict(board_kw or {})
    with tempfile.TemporaryDirectory(prefix="sphere-restarts-") as tmp:
        tmp = Path(tmp)
        trace = T.to_chips(T.still(seconds)).write(tmp / "trace.bin")
        if kind == "reboot":
            send = tmp / "send.txt"
            send.write_text("".join(f"{t:.4f} {encode_frame(Reboot(magic=REBOOT_MAGIC), i).hex(' ')}\n"
                                    for i, t in enumerate(times)))
            kw["send"] = send
        elif kind == "hang":
            kw["hang"] = [f"{t:.4f}:{t + HANG_S:.4f}" for t in times]
        else:
            kw["reset_at"] = times
        cap, ct = tmp / "cap.bin", tmp / "times.bin"
        r = run_board(elf, trace, seconds, cap, capture_times=ct, bootloader=bootloader, noise=True, seed=seed, **kw)
        if r.returncode:
            raise RuntimeError(f"the board failed: {r.stderr[-500:]}")
        frames = read_frames(cap.read_bytes(), ct.read_bytes())
    hellos = [(f.t_s, f.packet) for f in frames if f.ok and isinstance(f.packet, Hello)]
    first = hellos[0][1] if hellos else None
    events = []
    for i, t in enumerate(times):
        end = times[i + 1] if i + 1 < len(times) else seconds
        after = [(ht, h) for ht, h in hellos if t < ht <= end]
        if not after:
            events.append({"t": t, "latency_s": None, "cause": None, "bias_kept": None})
            continue
        ht, h = after[0]
        events.append({"t": t, "latency_s": round(ht - t, 4), "cause": h.reset_cause,
                       "bias_kept": bool(h.calibration_state & GYRO_BIAS_VALID),
                       "hellos": len(after)})
    lat = [e["latency_s"] for e in events if e["latency_s"] is not None]
    ok_causes = (EXPECTED_CAUSE[kind], 0)
    return {
        "bootloader": bootloader, "kind": kind, "count": count,
        "power_up_cause": first.reset_cause if first else None,
        "within_2s": sum(1 for x in lat if x <= 2.0),
        "max_latency_s": max(lat) if lat else None,
        "causes": sorted({e["cause"] for e in events if e["cause"] is not None}),
        "wrong_cause": sum(1 for e in events if e["cause"] is not None and e["cause"] not in ok_causes),
        "bias_kept": sum(1 for e in events if e["bias_kept"]),
        "extra_hellos": sum(e.get("hellos", 1) - 1 for e in events if e["latency_s"] is not None),
        "board_resets": r.stats.get("resets"),
        "events": events,
    }
