"""Scenarios for the end-to-end tests on the virtual board (hardware/sim): each one runs the board once
per test session (results cached) and returns the decoded capture and the board's stats.

Wall time: the board runs about 1.2 to 2.5 simulated seconds per wall second on this project's
2-core machines (`sphere sim` prints the ratio), so the scenarios are a few simulated seconds each.
"""

from __future__ import annotations

import functools
import os
import shutil
import signal
import subprocess
import time
import tempfile
from dataclasses import dataclass
from pathlib import Path

import pytest

from sphere.sim import trace as T
from sphere.sim.analysis import CaptureSummary, summarise
from sphere.sim.board import BoardUnavailable, board_path, firmware_elf, run_board, testfw_elf

TAPPING_TRIAL = "24_disturbed_tapping_A"
TAPPING_START_S = 48.0  # taps at 50.05, 52.99 and 56.50 s of the trial (still before the first)
TAPPING_HOLD_S = 1.0


@dataclass
class Scenario:
    name: str
    summary: CaptureSummary
    stats: dict
    capture: bytes
    returncode: int
    stderr: str
    trial: object = None


def need_board() -> Path:
    try:
        return board_path(build=True)
    except BoardUnavailable as e:
        pytest.skip(f"virtual board unavailable: {e}")


def need_firmware() -> Path:
    """The firmware image, made first when it is missing or older than firmware/src (sphere.sim.board.firmware_elf)."""
    try:
        return firmware_elf(build=True)
    except BoardUnavailable as e:
        pytest.skip(f"no firmware image to run: {e}")


def _need_sketch(what: str, make) -> Path:
    if shutil.which("avr-g++") is None or not Path("/usr/share/arduino/hardware/arduino/avr/cores/arduino").is_dir():
        pytest.skip(f"avr-g++ or Debian's arduino-core-avr missing: cannot build the board's {what}")
    try:
        return make(build=True)
    except BoardUnavailable as e:
        pytest.skip(str(e))


def need_testfw() -> Path:
    return _need_sketch("test sketch", testfw_elf)


def _run(name: str, elf: Path, motion: T.Motion, seconds: float, **kw) -> Scenario:
    with tempfile.TemporaryDirectory(prefix=f"sphere-e2e-{name}-") as tmp:
        trace = T.to_chips(motion).write(Path(tmp) / "trace.bin")
        cap = Path(tmp) / "capture.bin"
        r = run_board(elf, trace, seconds, cap, **kw)
        data = cap.read_bytes() if cap.exists() else b""
    return Scenario(name, summarise(data), r.stats, data, r.returncode, r.stderr)


def tapping_motion():
    from sphere.broad import BroadMissing, find_trial, load_trial

    try:
        trial = load_trial(find_trial(TAPPING_TRIAL))
    except BroadMissing as e:
        pytest.skip(str(e))
    sl = trial.seconds(TAPPING_START_S, 9.0)
    return T.hold_first(T.from_broad(sl), TAPPING_HOLD_S), trial


def tap_times_sim_s(motion: T.Motion, threshold_g: float) -> list[float]:
    """Simulated times of the taps as the ADXL345 model sees them: starts of spikes over threshold_g on
    any axis of the 200 Hz chip trace (BROAD's 285.7 Hz resampled), 0.3 s apart at least."""
    import numpy as np

    ct = T.to_chips(motion)
    a = np.abs(ct.accel_lsb.astype(float)).max(axis=1) / 256.0
    idx = np.where(a > threshold_g)[0]
    starts = [i for k, i in enumerate(idx) if k == 0 or i - idx[k - 1] > int(0.3 * ct.accel_rate_hz)]
    return [i / ct.accel_rate_hz for i in starts]


@functools.lru_cache(maxsize=None)
def firmware_scenario(name: str) -> Scenario:
    need_board()
    elf = need_firmware()
    if name == "tapping":
        motion, trial = tapping_motion()
        s = _run(name, elf, motion, 10.0)
        s.trial = motion
        return s
    if name == "toss":
        return _run(name, elf, T.toss(5.0, toss_at_s=2.5, flight_s=0.4), 5.0)
    if name == "mag_fault":
        return _run(name, elf, T.still(8.0), 8.0, nack=["hmc5883l:3:5"])
    if name == "stall":
        return _run(name, elf, T.still(6.0), 6.0, stall=["2.5:2.7"])
    if name == "commands":
        return _run_with_commands(name, elf, T.still(4.0), 4.0)
    raise KeyError(name)


def _command_lines(commands) -> str:
    from sphere.protocol import encode_frame

    return "".join(f"{t:.3f} {encode_frame(p, seq).hex(' ')}\n" for seq, (t, p) in enumerate(commands))


def _commands():
    from sphere.protocol import GetStatus, SetStream

    # at 1.5 s: orientation only at 50 Hz plus status; at 2.5 s: a bad rate (must change nothing); then GET_STATUS
    return [(1.5, SetStream(stream_mode=0b110, raw_rate_hz=0, orientation_rate_hz=50)),
            (2.5, SetStream(stream_mode=0b110, raw_rate_hz=0, orientation_rate_hz=7)),
            (3.0, GetStatus())]


def _run_with_commands(name, elf, motion, seconds) -> Scenario:
    with tempfile.TemporaryDirectory(prefix=f"sphere-e2e-{name}-") as tmp:
        send = Path(tmp) / "send.txt"
        send.write_text(_command_lines(_commands()))
        return _run(name, elf, motion, seconds, send=send)


@functools.lru_cache(maxsize=None)
def sketch_scenario(name: str) -> Scenario:
    need_board()
    elf = need_testfw()
    if name == "taps":
        return _run(name, elf, T.taps(4.0, at_s=(1.0, 2.0, 2.15)), 4.0)
    if name == "toss":
        return _run(name, elf, T.toss(4.0, toss_at_s=2.0), 4.0)
    if name == "nack":
        return _run(name, elf, T.still(5.0), 5.0, nack=["itg3200:1.5:3"])
    if name == "stall":
        return _run(name, elf, T.still(4.0), 4.0, stall=["1.5:1.6"])
    raise KeyError(name)


# ---------------------------------------------------------------- the bench I2C master (hardware/sim/probe)


@dataclass
class ProbeLine:
    t_us: int
    tag: str
    data: list  # bytes read, [] for a write / bus clear, None for a NACK


@dataclass
class ProbeRun:
    lines: list
    stats: dict
    stderr: str

    def tagged(self, tag: str) -> list:
        return [x for x in self.lines if x.tag == tag]


def need_probe() -> Path:
    from sphere.sim.board import probe_elf

    return _need_sketch("probe sketch", probe_elf)


def probe(commands, motion, seconds: float, **kw) -> ProbeRun:
    """Run the probe sketch on the board: ``commands`` are (simulated time s, "w 1e 02 00"-style text);
    ``motion`` a Motion or a ChipTrace (for chip rates other than the default trace's)."""
    need_board()
    elf = need_probe()
    with tempfile.TemporaryDirectory(prefix="sphere-probe-") as tmp:
        ct = motion if isinstance(motion, T.ChipTrace) else T.to_chips(motion)
        trace = ct.write(Path(tmp) / "trace.bin")
        send = Path(tmp) / "send.txt"
        send.write_text("".join(f"{t:.6f} {(c + chr(10)).encode().hex(' ')}\n" for t, c in commands))
        cap = Path(tmp) / "capture.bin"
        r = run_board(elf, trace, seconds, cap, send=send, **kw)
        text = cap.read_bytes().decode("latin-1") if cap.exists() else ""
    lines = []
    for ln in text.splitlines():
        parts = ln.split()
        if len(parts) < 2 or not parts[0].isdigit():
            continue
        try:
            data = None if parts[2:3] == ["NACK"] else [int(x, 16) for x in parts[2:] if x != "ok"]
        except ValueError:  # a line cut short by a reset of the AVR, then the next one
            continue
        lines.append(ProbeLine(int(parts[0]), parts[1], data))
    assert r.returncode == 0, r.stderr
    return ProbeRun(lines, r.stats, r.stderr)


def s16be(hi: int, lo: int) -> int:
    v = hi << 8 | lo
    return v - 65536 if v & 0x8000 else v


def s16le(lo: int, hi: int) -> int:
    return s16be(hi, lo)


# -- processes the tests start --------------------------------------------------------------------------------

def children(pid: int) -> list[int]:
    """The process ids of ``pid``'s children (Linux /proc)."""
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            return [int(p) for p in f.read().split()]
    except OSError:
        return []


def running(pid: int) -> bool:
    """``pid`` exists and is neither a zombie nor dead."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except OSError:
        return False


def survivors(pids, within_s: float = 10.0) -> list[int]:
    """Wait up to ``within_s`` for ``pids`` to end; those still running are killed and returned."""
    deadline = time.monotonic() + within_s
    while any(running(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    left = [p for p in pids if running(p)]
    for p in left:
        os.kill(p, signal.SIGKILL)
    return left


def stop_simulator(proc) -> None:
    """Stop `sphere sim`; its board stops with it (PR_SET_PDEATHSIG, test_sim_board.py checks that)."""
    if proc.poll() is None:
        proc.terminate()
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(5)
