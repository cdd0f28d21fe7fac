"""SAVE_CALIBRATION while the sphere turns, on the virtual board, whose EEPROM takes the ATmega328P's 3.4 ms a byte
(hardware/sim/README.md, "simavr 1.6's ATmega328P, corrected by the board"): does any sample period go missing, and
how far does the orientation stray from the same run without the save?

    from sphere.sim.storage import save_while_turning
    r = save_while_turning(firmware_elf(), dps=200)
    r["missed_periods"], r["max_diff_deg"]
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from sphere.protocol import SaveCalibration, encode_frame
from sphere.protocol.packets import Orientation, Reply, Status
from sphere.sim import trace as T
from sphere.sim.board import run_board
from sphere.sim.soak import read_frames

SAVE_AT_S = 3.0


def _orientations(frames):
    tq = [(f.t_s, f.packet.quat_float) for f in frames if f.ok and isinstance(f.packet, Orientation)]
    return np.array([t for t, _ in tq]), np.array([q for _, q in tq], dtype=float)


def _angle_deg(p, q) -> np.ndarray:
    d = np.abs(np.sum(p * q, axis=1)) / (np.linalg.norm(p, axis=1) * np.linalg.norm(q, axis=1))
    return np.degrees(2 * np.arccos(np.clip(d, -1.0, 1.0)))


def save_while_turning(elf, dps: float = 200.0, seconds: float = 5.0, seed: int = 1, bootloader=None) -> dict:
    """Two runs of a turn at ``dps`` about z (still 1 s first): one sends SAVE_CALIBRATION at SAVE_AT_S.
    Returns the REPLY's delay and result, the device's loop overruns and the board's missing updates in
    both, the EEPROM bytes written, and the largest angle between the two runs' ORIENTATIONs after the save."""
    out = {}
    with tempfile.TemporaryDirectory(prefix="sphere-save-") as tmp:
        tmp = Path(tmp)
        trace = T.to_chips(T.synthetic(f"rotation:{dps:g}", seconds)).write(tmp / "trace.bin")
        send = tmp / "send.txt"
        send.write_text(f"{SAVE_AT_S:.3f} {encode_frame(SaveCalibration(), 1).hex(' ')}\n")
        runs = {}
        for name in ("save", "reference"):
            cap, ct = tmp / f"{name}.cap", tmp / f"{name}.times"
            r = run_board(elf, trace, seconds, cap, capture_times=ct, send=send if name == "save" else None,
                          seed=seed, bootloader=bootloader)
            if r.returncode:
                raise RuntimeError(f"the board failed: {r.stderr[-500:]}")
            frames = read_frames(cap.read_bytes(), ct.read_bytes())
            statuses = [f.packet for f in frames if f.ok and isinstance(f.packet, Status)]
            runs[name] = frames
            out[name] = {"board_overruns": r.stats.get("overruns"), "updates": r.stats.get("updates"),
                         "device_loop_overruns": statuses[-1].loop_overruns if statuses else None,
                         "eeprom_writes": r.stats.get("eeprom_writes")}
    replies = [(f.t_s, f.packet) for f in runs["save"] if f.ok and isinstance(f.packet, Reply)]
    out["reply_after_s"] = round(replies[0][0] - SAVE_AT_S, 4) if replies else None
    out["reply_result"] = replies[0][1].result if replies else None
    ts, qs = _orientations(runs["save"])
    tr, qr = _orientations(runs["reference"])
    after = ts >= SAVE_AT_S
    # the same firmware on the same motion: the packets fall at the same simulated times (within a cycle or two)
    idx = np.clip(np.searchsorted(tr, ts[after]), 0, len(tr) - 1)
    same_t = np.abs(tr[idx] - ts[after]) < 1e-4
    out["compared"] = int(same_t.sum())
    out["max_diff_deg"] = float(_angle_deg(qs[after][same_t], qr[idx][same_t]).max()) if same_t.any() else None
    out["missed_periods"] = out["save"]["board_overruns"]  # periods without a MARG update (the timing pin)
    return out
