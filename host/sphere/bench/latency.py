"""Motion onset → X pointer move, end to end: the real firmware on the virtual board in real time, each USB-serial
adapter model, ``sphere-mouse --backend x11`` on a private Xvfb, the pointer read back thousands of times a second.

Rows (each a fresh board and daemon; every row in the same run, side by side):

- ``none``: bytes reach the host as they leave the UART (a native-USB board's best case);
- ``ch340``: the CH340 model (32-byte packets, sent at every 1 ms USB frame);
- ``ftdi``: the FT232R model with the host's low-latency request honoured (what sphere-mouse asks by default:
  latency timer 1 ms; hardware/sim/README.md, "The host's requests");
- ``ftdi-16ms``: the same with ``[source] low_latency = false`` (the driver's default 16 ms latency timer: what
  every earlier sphere-mouse got), the row the others are compared with.

Motion: ``synthetic:onsets`` (:mod:`sphere.sim.onsets`): sharp 120 °/s turns starting at known simulated times,
at every phase of the 5 ms sample clock. For each onset the pointer's first move after it is found in the
pointer record, and its latency is split where the path can be split (all from the board's ``--host-log``):

- ``age``: onset → the firmware starts sending the frame that moved the pointer (waiting for the sample period,
  the ITG-3200's 98 Hz DLPF and its register refreshed every 1 ms, the reads, queueing behind other frames; and
  a sample period more when the first moving sample does not add up to a pixel yet);
- ``wire``: that frame's first byte → its delimiter at the UART (its length at the baud rate; at 115200 with the
  MARG update's 0.6 ms pause in it: RAW_SAMPLE is sent before the update, firmware/README.md);
- ``adapter``: the delimiter leaves the UART → the adapter hands the packet to the host (the pty write);
- ``host``: the pty write → the X pointer moved (the daemon's read, decoding, filters, XTest, the X server). The
  pointer is watched as any X client can see it move: the server's ``MotionNotify`` for each move, the time being
  when it reached the watching client (``--pointer events``, the default). ``--pointer poll`` reads the pointer
  with ``XQueryPointer`` instead, about 3,000 times a second: that adds the reads' period (0.3 ms median, 0.7–0.9
  ms at p99 on an idle machine) to every host stage and keeps the X server busy answering. This tree's daemon
  writes each move's read and call times (``sphere-mouse --move-log``), so its rows split the host stage in
  three (:data:`HOST_SPLIT`): the wake-up to the daemon's read, the daemon's work and XTest call, the display
  server's part up to the watch.

The frame that moved the pointer: of the pty writes before the move, the last one that carried the turn (a
RAW_SAMPLE sent after the onset with a non-zero gyro reading: the board runs without noise), and in it the first
such RAW_SAMPLE (an FTDI packet holds several frames; the daemon moves at the first that adds up to a pixel).
A move with no such frame before it is counted as unattributed. ``total`` = age + wire + adapter + host. The board paces itself to
the wall clock and writes no packet before its simulated time; ``lag`` (the write's wall time minus its
simulated time) is how late it was, left out of ``total`` and printed so that a run on a loaded machine shows.
The last column, ``daemon loop``, is how the kernel scheduled sphere-mouse's loop during the row, read from /proc
(``SCHED_FIFO 5`` where it was allowed real time: :mod:`sphere.daemon.priority`): the host stage's tail depends on
it, so no figure is printed without it.

The virtual board stands in for the sphere and its USB adapter, which on a desk have chips of their own, and the
pointer sampler is the measuring instrument; on a machine whose cores are busy both wait for a core, and what
they lose shows as ``lag`` (the board behind the wall clock) and as moves seen late (the sampler's gaps). So both
run at nice ``--instruments-nice`` (−10; 0 = as the bench itself) where the bench may lower it, and the line
above the table says how the board, the sampler and Xvfb were scheduled. Xvfb stands in for the desktop's display
server and runs as the bench does unless ``--xvfb-nice`` says otherwise; the daemon as it asks for itself.

``--against REV`` runs every row twice, side by side in the same run: with this tree's sphere-mouse and with the
sphere-mouse of git revision REV (its ``host/`` from ``git archive``, on ``PYTHONPATH``; the same firmware, board,
X server and pointer sampler), the two in alternating order, and prints this tree's figures over REV's.
"""

from __future__ import annotations

import argparse
import array
import contextlib
import gc
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sphere import argtypes
from sphere.bench import _latency_floor as F
from sphere.bench._revision import RevisionError, tree_of
from sphere.bench._xvfb import PointerEvents, PointerReader, Xvfb, XvfbUnavailable
from sphere.daemon.move_log import read_move_log
from sphere.daemon.priority import thread_scheduling
from sphere.errors import SphereError
from sphere.protocol import FrameDecoder, RawSample
from sphere.protocol.packets import FAST_BAUDS
from sphere.sim import onsets as O
from sphere.sim import trace as T
from sphere.sim.board import board_command, firmware_elf, start_pty_board

HELP = ("motion onset -> X pointer move through the virtual board: each USB adapter model and baud, "
        "sphere-mouse --backend x11 on Xvfb, latency per stage (percentiles)")

#: row name -> (the board's --adapter, the host asks for low latency)
ADAPTERS = {"none": (None, True), "ch340": ("ch340", True), "ftdi": ("ftdi", True), "ftdi-16ms": ("ftdi", False)}
BASELINE = "ftdi-16ms"
STAGES = ("age", "wire", "adapter", "host")
#: the host stage split by the daemon's --move-log (this tree's rows): the pty write → the daemon's read returned;
#: → its XTest call returned (decoding, the filters, the mapping, the call); → the pointer watch saw the move (the
#: X server, its report to the watch)
HOST_SPLIT = ("host_to_read", "host_daemon", "host_display")


class RowFailed(SphereError, RuntimeError):
    """One row could not be measured (its daemon never reported the link, e.g. a baud switch that fell back on a
    loaded machine): the run goes on with the other rows and says which one failed."""


#: the nice value of the virtual board and the pointer sampler unless --instruments-nice says otherwise
INSTRUMENTS_NICE = -10
#: a row whose pointer sampler went this long without a read is named under the table
SAMPLER_GAP_NOTE_MS = 5.0
#: how the pointer's moves are seen (--pointer; PointerRecorder)
POINTER_WATCH = ("events", "poll")
#: writes of the host stage's floor (sphere.bench._latency_floor) before the rows
FLOOR_WRITES = 1000
#: a move this long after its onset is not this onset's (the next comes PERIOD_S later)
MOVE_WINDOW_S = 0.25


def add_arguments(p) -> None:
    p.add_argument("--seconds", type=argtypes.seconds_up_to(3600.0), default=20.0,
                   help="simulated (= wall) seconds per row, the first 3 still (default 20: 42 onsets a row)")
    p.add_argument("--adapters", type=_adapter_list, default=list(ADAPTERS),
                   help=f"comma-separated rows among {', '.join(ADAPTERS)} (default all)")
    p.add_argument("--bauds", type=_baud_list, default=[115200, 1000000],
                   help="comma-separated rates the link runs at: 115200, or 250000/500000/1000000 that sphere-mouse "
                        "switches the sphere to (SET_BAUD; default 115200,1000000)")
    p.add_argument("--seed", type=argtypes.count, default=27, help="seed of the onsets' phases (default 27)")
    p.add_argument("--no-monitor", action="store_true",
                   help="leave out the check of `sphere monitor`'s sample age against the board's truth")
    p.add_argument("--json", metavar="OUT", type=argtypes.out_file, help="also write every figure as JSON")
    p.add_argument("--instruments-nice", type=_nice_value, default=INSTRUMENTS_NICE, metavar="N",
                   help="nice value of the virtual board (the sphere's stand-in) and the pointer sampler (the "
                        f"instrument), -20..0 (default {INSTRUMENTS_NICE}; 0 = as the bench runs)")
    p.add_argument("--xvfb-nice", type=_nice_value, default=0, metavar="N",
                   help="nice value of Xvfb, the display server's stand-in, -20..0 (default 0: as the bench runs; "
                        "what a desktop's display server gets is the desktop's)")
    p.add_argument("--pointer", choices=POINTER_WATCH, default=POINTER_WATCH[0],
                   help="how the X pointer's moves are seen: events (the server's MotionNotify for each move, as it "
                        "makes it; default) or poll (XQueryPointer about 3,000 times a second: the reads' period is "
                        "added to the host stage)")
    p.add_argument("--floor-writes", type=argtypes.count, default=FLOOR_WRITES, metavar="N",
                   help="writes of the host stage's floor measured before the rows (a relay doing no work between the "
                        f"pty and XTest, through libXtst and through python-xlib; default {FLOOR_WRITES}, 0 = leave it "
                        "out)")
    p.add_argument("--against", metavar="REV", help="also run every row with the sphere-mouse of this git revision "
                                                   "(say main before a change), side by side, in alternating order")


def _nice_value(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number: a nice value from -20 to 0") from None
    if not -20 <= value <= 0:
        raise argparse.ArgumentTypeError(f"{value}: a nice value from -20 to 0 (lower runs first)")
    return value


def _adapter_list(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    bad = [n for n in names if n not in ADAPTERS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"unknown adapter row {', '.join(bad) or repr(text)}: "
                                         f"choose among {', '.join(ADAPTERS)}")
    return names


def _baud_list(text: str) -> list[int]:
    bauds = [argtypes.baud(b.strip()) for b in text.split(",") if b.strip()]
    if not bauds:
        raise argparse.ArgumentTypeError(f"no baud rate in {text!r}: e.g. 115200 or 115200,1000000")
    for b in bauds:
        if b != 115200 and b not in FAST_BAUDS:
            raise argparse.ArgumentTypeError(f"baud {b}: the sphere runs at 115200, or at "
                                             f"{', '.join(map(str, FAST_BAUDS))} after SET_BAUD")
    return bauds


# ---------------------------------------------------------------------------------------------------- the record


@dataclass
class HostLog:
    """The board's --host-log: T0, frames at the UART (U), pty writes (P), one entry per delimiter."""

    t0_ns: int
    uart: list  # (first byte s, delimiter s) per frame
    pty: list  # (simulated s, monotonic ns) per delimiter
    periods: list = field(default_factory=list)  # (simulated s, monotonic ns) at each sample period's start

    @classmethod
    def read(cls, path: Path) -> "HostLog":
        t0, uart, pty, periods = 0, [], [], []
        for line in path.read_text().splitlines():
            f = line.split()
            if f[0] == "T0":
                t0 = int(f[1])
            elif f[0] == "U":
                uart.append((float(f[1]), float(f[2])))
            elif f[0] == "P":
                pty.extend([(float(f[1]), int(f[2]))] * int(f[3]))
            elif f[0] == "S":
                periods.append((float(f[1]), int(f[2])))
        return cls(t0, uart, pty, periods)


@dataclass
class Frame:
    uart_start_s: float
    uart_end_s: float
    pty_s: float
    pty_ns: int
    moving: bool  # a RAW_SAMPLE with a non-zero gyro reading
    raw: bool = False  # a RAW_SAMPLE


def frames_of(capture: bytes, log: HostLog) -> list[Frame]:
    """Every frame the host received, in order, with its times at the UART and at the pty."""
    chunks = capture.split(b"\x00")[:-1]  # one per delimiter (the text after the last one is unfinished)
    decoder = FrameDecoder("device")
    out, u = [], 0
    for j, chunk in enumerate(chunks):
        if not chunk:
            continue
        if j >= len(log.pty) or u >= len(log.uart):
            break
        got = decoder.feed(chunk + b"\x00")
        p = got[0] if got else None
        moving = p is not None and p.TYPE == RawSample.TYPE and any(p.gyro)
        start, end = log.uart[u]
        out.append(Frame(start, end, *log.pty[j], moving, p is not None and p.TYPE == RawSample.TYPE))
        u += 1
    return out


def pointer_moves(samples: np.ndarray, after_ns: int, until_ns: int):
    """(time ns, x, y) of the first sample after ``after_ns`` (and before ``until_ns``) whose position differs from
    the position at ``after_ns``; None when the pointer did not move."""
    t = samples[:, 0]
    i = int(np.searchsorted(t, after_ns, side="right"))
    if i == 0 or i >= len(t):
        return None
    x0, y0 = samples[i - 1, 1], samples[i - 1, 2]
    moved = np.nonzero((samples[i:, 1] != x0) | (samples[i:, 2] != y0))[0]
    if not len(moved):
        return None
    k = i + int(moved[0])
    return None if t[k] > until_ns else (int(t[k]), int(samples[k, 1]), int(samples[k, 2]))


def attribute(onsets_s, connected_ns: int, frames: list[Frame], samples: np.ndarray, t0_ns: int,
              moves=None) -> dict:
    """Per onset: the pointer's first move and the stages of the frame that moved it (module docstring). With the
    daemon's ``moves`` (its --move-log: read ns, moved ns per move) the host stage splits too (:data:`HOST_SPLIT`):
    the daemon's last move call before the pointer was seen to move, when its read came after the frame's write."""
    stages = {k: [] for k in (*STAGES, "total", "lag")}
    if moves is not None:
        stages.update({k: [] for k in HOST_SPLIT})
        moved_ns = np.array([m[1] for m in moves], dtype=np.int64)
    missed = unattributed = skipped = 0
    pty_ns = np.array([f.pty_ns for f in frames], dtype=np.int64)
    for t_on in onsets_s:
        on_ns = t0_ns + int(round(t_on * 1e9))
        if on_ns < connected_ns:
            skipped += 1
            continue
        # the pointer's position when the board reached the onset: its last write before the onset
        before = [f for f in frames if f.uart_end_s <= t_on]
        start_ns = max(on_ns, before[-1].pty_ns if before else on_ns)
        move = pointer_moves(samples, start_ns, on_ns + int(MOVE_WINDOW_S * 1e9) + (start_ns - on_ns))
        if move is None:
            missed += 1
            continue
        w = int(np.searchsorted(pty_ns, move[0], side="right"))  # frames written before the move: [:w]
        carrying = [i for i in range(w) if frames[i].moving and frames[i].uart_start_s >= t_on]
        if not carrying:
            unattributed += 1
            continue
        write_ns = frames[carrying[-1]].pty_ns  # the last write before the move that carried the turn
        trigger = frames[next(i for i in carrying if frames[i].pty_ns == write_ns)]
        parts = {"age": trigger.uart_start_s - t_on, "wire": trigger.uart_end_s - trigger.uart_start_s,
                 "adapter": trigger.pty_s - trigger.uart_end_s, "host": (move[0] - trigger.pty_ns) / 1e9}
        for k, v in parts.items():
            stages[k].append(v * 1e3)
        stages["total"].append(sum(parts.values()) * 1e3)
        if moves is not None:
            m = int(np.searchsorted(moved_ns, move[0], side="right")) - 1
            if m >= 0 and moves[m][0] >= trigger.pty_ns:
                read, called = moves[m]
                for k, a, b in zip(HOST_SPLIT, (trigger.pty_ns, read, called), (read, called, move[0])):
                    stages[k].append((b - a) / 1e6)
        stages["lag"].append((trigger.pty_ns - t0_ns) / 1e6 - trigger.pty_s * 1e3)
    return {"ms": stages, "missed": missed, "unattributed": unattributed, "skipped": skipped}


def percentiles(values) -> dict:
    if not values:
        return {"n": 0}
    a = np.asarray(values, dtype=float)
    return {"n": len(a), "p50": float(np.percentile(a, 50)), "p95": float(np.percentile(a, 95)),
            "p99": float(np.percentile(a, 99)), "max": float(a.max())}


# ---------------------------------------------------------------------------------------------------- one row


class PointerRecorder(threading.Thread):
    """Keeps each change of the X pointer with its time: ``watch="events"``, each ``MotionNotify`` the server sends
    (:class:`PointerEvents`: the time is when the move reached this client, woken by its socket); ``"poll"``, the
    pointer read every 0.2 ms or so (the sleep plus one round trip), a change timed when the read that saw it returned.

    A move seen late is timed late, and counted in the wrong stage: the frames written meanwhile make it look like
    a late frame (``age``). So what it keeps goes into flat arrays of integers (no object per read for Python's
    garbage collector to count), and :func:`run_row` holds this process's automatic collection off while a row runs
    (a full one takes ≈20 ms here, idle). When polling, the longest gap between reads is in the JSON and named under
    the table when over :data:`SAMPLER_GAP_NOTE_MS`."""

    def __init__(self, display: str, nice: int = 0, watch: str = "events"):
        super().__init__(daemon=True)
        self.watch = watch
        self.reader = PointerEvents(display) if watch == "events" else PointerReader(display)
        self.nice = nice
        self.scheduling = "unknown"  # how the sampler ran (sphere.daemon.priority.thread_scheduling)
        self.stop = threading.Event()
        self._changes = array.array("q")  # (monotonic ns, x, y) per change, flat
        self.reads = 0  # reads (poll) or moves reported (events)
        self.gaps_ns = array.array("q")  # poll: the time between reads

    @property
    def changes(self) -> np.ndarray:
        """(monotonic ns, x, y) of each change, as rows."""
        return np.asarray(self._changes, dtype=np.int64).reshape(-1, 3)

    def run(self):
        tid = threading.get_native_id()
        if self.nice:
            with contextlib.suppress(OSError):  # not allowed: it runs as the bench does, and says so
                os.setpriority(os.PRIO_PROCESS, tid, self.nice)
        self.scheduling = thread_scheduling(os.getpid(), tid)
        pos = self.reader.position()
        self._changes.extend((time.monotonic_ns(), *pos))
        try:
            (self._listen if self.watch == "events" else self._poll)(pos)
        finally:
            self.reader.close()

    def _listen(self, pos):
        keep, reader = self._changes.extend, self.reader
        while not self.stop.is_set():
            if not reader.wait(0.05):
                continue
            now = time.monotonic_ns()  # when the server's report woke this thread
            for p in reader.moves():
                self.reads += 1
                if p != pos:
                    pos = p
                    keep((now, *p))
        keep((time.monotonic_ns(), *pos))

    def _poll(self, pos):
        last = time.monotonic_ns()
        keep = self._changes.extend
        gap = self.gaps_ns.append
        while not self.stop.is_set():
            p = self.reader.position()
            now = time.monotonic_ns()
            self.reads += 1
            gap(now - last)
            last = now
            if p != pos:
                pos = p
                keep((now, *p))
            time.sleep(0.0002)  # about 3,000 reads a second on an idle machine: the sampler's period stays well under 1 ms
        keep((time.monotonic_ns(), *pos))


@contextlib.contextmanager
def niced(value: int):
    """The calling thread at nice ``value`` while the block runs, so that a process it starts begins there; as it
    was if that is not allowed (the process started then says how it runs: thread_scheduling)."""
    tid = threading.get_native_id()
    before = os.getpriority(os.PRIO_PROCESS, tid)
    try:
        if value:
            os.setpriority(os.PRIO_PROCESS, tid, value)
    except OSError:
        pass
    try:
        yield
    finally:
        os.setpriority(os.PRIO_PROCESS, tid, before)  # up again: always allowed


#: the row's tree when --against is not given (or for this tree's rows beside it)
THIS = "this"


def run_row(name: str, baud: int, trace: Path, onsets_s, seconds: float, display: str, tmp: Path, elf,
            tree: str = THIS, host_dir: str | None = None, instruments_nice: int = 0, pointer: str = "events") -> dict:
    """One row; ``host_dir``: the ``host/`` folder whose sphere-mouse runs (another revision's, --against), else
    this tree's; ``instruments_nice``: the board's and the sampler's nice value (module docstring); ``pointer``: how
    the pointer's moves are seen (:class:`PointerRecorder`)."""
    adapter, low_latency = ADAPTERS[name]
    log_path, cap_path = tmp / f"{name}-{baud}-{tree}.log", tmp / f"{name}-{baud}-{tree}.cap"
    moves_path = tmp / f"{name}-{baud}-{tree}.moves" if host_dir is None else None  # another revision may lack it
    with niced(instruments_nice):
        board, pty = start_pty_board(board_command(elf, trace, seconds, capture=cap_path, pty=True, adapter=adapter,
                                                   host_log=log_path))
    board_scheduling = thread_scheduling(board.pid)
    mouse = None
    recorder = PointerRecorder(display, instruments_nice, pointer)
    collecting = gc.isenabled()
    gc.disable()  # no collection in this process stalls the pointer sampler during the row (PointerRecorder)
    recorder.start()
    try:
        env = None
        if host_dir is not None:  # -P: that tree's package, never one in the current folder
            env = dict(os.environ, PYTHONPATH=host_dir)
        mouse_cmd = [sys.executable, "-P", "-m", "sphere.mouse", "--port", pty, "--backend", "x11",
                     "--display", display, "--no-stream", "--quiet", "--config", os.devnull,
                     "--set", f"source.low_latency={'true' if low_latency else 'false'}",
                     "--set", f"source.baud_switch={0 if baud == 115200 else baud}"]
        if moves_path is not None:
            mouse_cmd += ["--move-log", str(moves_path)]
        mouse = subprocess.Popen(mouse_cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
        connected = {}

        def watch():
            for line in mouse.stderr:  # found, then (with --bauds above 115200) switched: the rate measured
                if ("link at" in line if baud != 115200 else "sphere found on" in line) and "ns" not in connected:
                    connected["ns"] = time.monotonic_ns()
                connected.setdefault("lines", []).append(line.rstrip())

        watcher = threading.Thread(target=watch, daemon=True)
        watcher.start()
        board.wait(seconds * 4 + 60)
        # how the daemon's loop (its main thread) was scheduled, as the kernel applies it: no figure without it
        scheduling = thread_scheduling(mouse.pid) if mouse.poll() is None else "unknown (the daemon had ended)"
    finally:
        recorder.stop.set()
        recorder.join(5)
        if collecting:
            gc.enable()
        for proc in (mouse, board):
            if proc is not None and proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(10)
                except subprocess.TimeoutExpired:
                    proc.kill()
    if "ns" not in connected:
        raise RowFailed("sphere-mouse did not find the virtual board: " + " | ".join(connected.get("lines", [])[-3:]))
    log = HostLog.read(log_path)
    frames = frames_of(cap_path.read_bytes(), log)
    samples = recorder.changes
    # from 0.5 s after the daemon found the port: its start-up (HELLO, gyro bias) is not the steady state
    moves = read_move_log(moves_path) if moves_path is not None and moves_path.exists() else None
    got = attribute(onsets_s, connected["ns"] + 500_000_000, frames, samples, log.t0_ns, moves)
    gaps = np.asarray(recorder.gaps_ns, dtype=float) / 1e6
    fell_back = any("back to 115200" in line for line in connected.get("lines", []))
    row = {"row": name, "baud": baud, "tree": tree, "daemon_scheduling": scheduling,
           "board_scheduling": board_scheduling, "sampler_scheduling": recorder.scheduling,
           "fell_back_to_115200": fell_back, "onsets": len(onsets_s),
           "moves": len(got["ms"]["total"]),
           "missed": got["missed"], "unattributed": got["unattributed"], "skipped_before_connect": got["skipped"],
           "stages_ms": {k: percentiles(v) for k, v in got["ms"].items()}, "pointer": pointer}
    if pointer == "events":
        row["pointer_moves_reported"] = recorder.reads
    else:
        row["pointer_reads_per_s"] = recorder.reads / max(1e-9, gaps.sum() / 1e3)
        row["pointer_read_gap_ms"] = ({"p50": float(np.percentile(gaps, 50)), "p99": float(np.percentile(gaps, 99)),
                                       "max": float(gaps.max())} if len(gaps) else {})
    return row


#: the XTest libraries the floor is measured through, in the order printed (X11Backend's ``via``)
FLOOR_VIA = ("libXtst", "python-xlib")


def host_floor(display: str, writes: int, instruments_nice: int, pointer: str) -> list[dict]:
    """The host stage with none of the daemon's work (:mod:`sphere.bench._latency_floor`), once through each library
    the x11 backend can send XTest with (:data:`FLOOR_VIA`), seen by the same pointer watch as the rows, the writer
    at the board's nice value; the write → move times as :func:`percentiles`."""

    def watch(d):
        recorder = PointerRecorder(d, instruments_nice, pointer)
        recorder.start()
        return recorder

    collecting = gc.isenabled()
    gc.disable()
    try:
        out = []
        for via in FLOOR_VIA:
            with niced(instruments_nice):
                m = F.measure(display, watch, writes, via)
            out.append(dict(m, ms=percentiles(m["ms"])))
        return out
    finally:
        if collecting:
            gc.enable()


def true_ages(frames: list[Frame], log: HostLog, from_ns: int, to_ns: int) -> list[float]:
    """The true age (ms) of each RAW_SAMPLE written to the pty between ``from_ns`` and ``to_ns``: its pty write's wall
    time minus the moment its sample period began (the sample clock's interrupt; the firmware stamps t_us right
    after it). That moment on the wall clock is its simulated time from T0, or later if the board ran behind."""
    starts = np.array([s for s, _ in log.periods])
    out = []
    for f in frames:
        if not f.raw or not from_ns <= f.pty_ns <= to_ns:
            continue
        k = int(np.searchsorted(starts, f.uart_start_s, side="right")) - 1
        if k < 0:
            continue
        sim_s, wall_ns = log.periods[k]
        began_ns = max(log.t0_ns + int(round(sim_s * 1e9)), wall_ns)
        out.append((f.pty_ns - began_ns) / 1e6)
    return out


def monitor_check(trace: Path, seconds: float, tmp: Path, elf, instruments_nice: int = 0) -> dict:
    """`sphere monitor` on the FTDI board (low latency, 115200): its last view's sample age against the truth of the
    board's log over the same last 2 s."""
    log_path, cap_path = tmp / "monitor.log", tmp / "monitor.cap"
    with niced(instruments_nice):
        board, pty = start_pty_board(board_command(elf, trace, seconds, capture=cap_path, pty=True, adapter="ftdi",
                                                   host_log=log_path))
    try:
        r = subprocess.run([sys.executable, "-m", "sphere.cli", "monitor", "--port", pty, "--seconds",
                            f"{max(4.0, seconds - 3.0):g}"], capture_output=True, text=True, timeout=seconds * 4 + 60)
        ended_ns = time.monotonic_ns()
        board.wait(seconds * 4 + 60)
    finally:
        if board.poll() is None:
            board.terminate()
            board.wait(10)
    m = re.search(r"sample age: median ([-\d.]+) ms, p95 ([-\d.]+) ms \(last 2 s", r.stdout)
    if not m:
        raise RuntimeError("sphere monitor showed no sample age: " + (r.stdout + r.stderr).strip()[-300:])
    log = HostLog.read(log_path)
    frames = frames_of(cap_path.read_bytes(), log)
    truth = true_ages(frames, log, ended_ns - 2_000_000_000, ended_ns)
    t = percentiles(truth)
    shown = {"p50": float(m.group(1)), "p95": float(m.group(2))}
    return {"monitor_ms": shown, "truth_ms": t,
            "difference_ms": {k: shown[k] - t[k] for k in ("p50", "p95")} if t.get("n") else {}}


# ---------------------------------------------------------------------------------------------------- the bench


def run(args) -> int:
    onsets_s = O.onset_times(args.seconds, args.seed)
    if not len(onsets_s):
        print(f"sphere bench latency: --seconds {args.seconds:g} leaves no onset (the first comes at "
              f"{O.LEAD_S:g} s): give at least {O.LEAD_S + O.PERIOD_S:g}", file=sys.stderr)
        return 2
    revision = against_dir = None
    if args.against:  # that revision's host/ first: a wrong name is a usage error before any work
        revision = tempfile.TemporaryDirectory(prefix="sphere-latency-rev-")
        try:
            against_dir = tree_of(args.against, revision.name)
        except RevisionError as e:
            revision.cleanup()
            print(f"sphere bench latency: {e}", file=sys.stderr)
            return 2
    try:
        elf = firmware_elf()
        with niced(args.xvfb_nice):
            xvfb = Xvfb()
    except (XvfbUnavailable, RuntimeError, OSError) as e:
        if revision is not None:
            revision.cleanup()
        print(f"sphere bench latency: {e}", file=sys.stderr)
        return 1
    xvfb_scheduling = thread_scheduling(xvfb.proc.pid)
    rows, failed = [], []
    monitor = floor = None
    load_before = os.getloadavg()[0]
    try:
        if args.floor_writes:
            print(f"  the host stage's floor: {args.floor_writes} writes ...", file=sys.stderr, flush=True)
            floor = host_floor(xvfb.display, args.floor_writes, args.instruments_nice, args.pointer)
        with tempfile.TemporaryDirectory(prefix="sphere-latency-") as tmp:
            tmp = Path(tmp)
            trace = T.to_chips(O.onsets(args.seconds, args.seed), gyro_rate_hz=1000.0).write(tmp / "onsets.bin")
            sides = [(THIS, None)] + ([(args.against, against_dir)] if args.against else [])
            k = 0
            for baud in args.bauds:
                for name in args.adapters:
                    for tree, host_dir in (sides if k % 2 == 0 else sides[::-1]):  # who goes first alternates
                        side = f" ({tree})" if args.against else ""
                        print(f"  {name} at {baud} baud{side}: {args.seconds:g} s ...", file=sys.stderr, flush=True)
                        try:
                            rows.append(run_row(name, baud, trace, onsets_s, args.seconds, xvfb.display, tmp, elf,
                                                tree, host_dir, args.instruments_nice, args.pointer))
                        except RowFailed as e:
                            failed.append({"row": name, "baud": baud, "tree": tree, "error": str(e)})
                    k += 1
            if not args.no_monitor:
                print(f"  sphere monitor's sample age against the board's truth: {args.seconds:g} s ...",
                      file=sys.stderr, flush=True)
                monitor = monitor_check(trace, args.seconds, tmp, elf, args.instruments_nice)
    except RuntimeError as e:  # BoardUnavailable, a daemon that did not start
        print(f"sphere bench latency: {e}", file=sys.stderr)
        return 1
    finally:
        xvfb.close()
        if revision is not None:
            revision.cleanup()
    result = {"seconds_per_row": args.seconds, "seed": args.seed, "load_average": [load_before, os.getloadavg()[0]],
              "instruments_nice": args.instruments_nice, "xvfb_nice": args.xvfb_nice, "xvfb_scheduling": xvfb_scheduling,
              "pointer": args.pointer,
              "against": args.against, "host_floor": floor, "rows": rows, "failed_rows": failed, "sample_age": monitor}
    report(result)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=2)
    return 1 if failed else 0


def _tree(r) -> str:
    return r.get("tree", THIS)


def _watch(r) -> str:
    """The pointer column: how the row saw the pointer (reads a second when it polled)."""
    return f"{r['pointer_reads_per_s']:.0f}/s" if "pointer_reads_per_s" in r else r.get("pointer", "-")


def report(result: dict) -> None:
    rows = result["rows"]
    against = result.get("against")
    base = {(r["baud"], _tree(r)): r for r in rows if r["row"] == BASELINE}
    print(f"motion onset -> X pointer move, ms ({result['seconds_per_row']:g} s a row, seed {result['seed']}; "
          f"load average {result['load_average'][0]:.1f} -> {result['load_average'][1]:.1f})")
    seen = sorted({f"the virtual board {r['board_scheduling']}, the pointer sampler {r['sampler_scheduling']}"
                   for r in rows if "board_scheduling" in r})
    if seen:
        print(f"scheduling (--instruments-nice {result.get('instruments_nice', 0)}, --xvfb-nice "
              f"{result.get('xvfb_nice', 0)}): " + "; ".join(seen)
              + f"; Xvfb {result.get('xvfb_scheduling', 'unknown')}; the daemon's loop: the last column")
    for floor in result.get("host_floor") or ():
        m = floor["ms"]
        if m.get("n"):
            print(f"host stage's floor (pty -> a relay doing no work, {floor['relay_scheduling']} -> XTest through "
                  f"{floor['via']} -> the pointer watch; {m['n']} writes): p50 {m['p50']:.2f}  p95 {m['p95']:.2f}  "
                  f"p99 {m['p99']:.2f}  max {m['max']:.2f} ms")
    tw = max([len(THIS)] + [len(_tree(r)) for r in rows]) if against else 0
    tree_head = f"{'daemon':<{tw}} " if against else ""
    head = (f"{'adapter':<10} {'baud':>7} {tree_head}{'moves':>7} {'total p50':>9} {'p95':>6} {'p99':>6} {'max':>6} "
            f"{'vs 16ms':>7} | {'age p50':>7} {'p95':>5} | {'wire':>5} | {'adapter p50':>11} {'p95':>5} | "
            f"{'host p50':>8} {'p95':>5} {'p99':>5} | {'lag p95':>7} {'pointer':>7} | daemon loop")
    print(head)
    for r in rows:
        s = r["stages_ms"]

        def f(stage, p, width=6):
            v = s[stage].get(p)
            return f"{v:{width}.2f}" if v is not None else " " * (width - 1) + "-"

        b = base.get((r["baud"], _tree(r)))
        ratio = (f"{s['total']['p95'] / b['stages_ms']['total']['p95']:7.2f}"
                 if b and b is not r and s["total"].get("p95") and b["stages_ms"]["total"].get("p95") else "      -")
        tree = f"{_tree(r):<{tw}} " if against else ""
        print(f"{r['row']:<10} {r['baud']:>7} {tree}{r['moves']:>3}/{r['onsets'] - r['skipped_before_connect']:<3} "
              f"{f('total', 'p50', 9)} {f('total', 'p95')} {f('total', 'p99')} {f('total', 'max')} {ratio} | "
              f"{f('age', 'p50', 7)} {f('age', 'p95', 5)} | {f('wire', 'p50', 5)} | {f('adapter', 'p50', 11)} "
              f"{f('adapter', 'p95', 5)} | {f('host', 'p50', 8)} {f('host', 'p95', 5)} {f('host', 'p99', 5)} | "
              f"{f('lag', 'p95', 7)} {_watch(r):>7} | {r.get('daemon_scheduling', '-')}")
    split = [r for r in rows if r["stages_ms"].get(HOST_SPLIT[0], {}).get("n")]
    if split:
        print("the host stage split (sphere-mouse --move-log), ms p50/p95/p99: pty write -> the daemon's read | "
              "-> its XTest call returned | -> the watch saw the move")
        for r in split:
            tree = f" {_tree(r):<{tw}}" if against else ""
            cells = [" / ".join(f"{r['stages_ms'][k][p]:.2f}" for p in ("p50", "p95", "p99")) for k in HOST_SPLIT]
            print(f"  {r['row']:<10} {r['baud']:>7}{tree} {r['stages_ms'][HOST_SPLIT[0]]['n']:>4} onsets: "
                  + " | ".join(cells))
    if against:
        side_by_side(rows, against)

    def who(r):
        return f"{r['row']} at {r['baud']}" + (f" ({_tree(r)})" if against else "")

    notes = [f"{who(r)}: {r['missed']} onsets without a move, {r['unattributed']} unattributed"
             for r in rows if r["missed"] or r["unattributed"]]
    notes += [f"{who(r)}: the daemon fell back to 115200 during the row" for r in rows if r.get("fell_back_to_115200")]
    held = [f"{who(r)} {r['pointer_read_gap_ms']['max']:.1f}" for r in rows
            if r.get("pointer_read_gap_ms", {}).get("max", 0) > SAMPLER_GAP_NOTE_MS]
    if held:
        notes.append("the pointer sampler went without a read for longer than "
                     f"{SAMPLER_GAP_NOTE_MS:g} ms (a move in such a gap is seen late), longest in ms: " + ", ".join(held))
    notes += [f"{who(r)}: FAILED, not measured: {r['error']}" for r in result.get("failed_rows", ())]
    if notes:
        print("; ".join(notes))
    age = result.get("sample_age")
    if age and age["truth_ms"].get("n"):
        shown, truth, diff = age["monitor_ms"], age["truth_ms"], age["difference_ms"]
        print(f"sample age (ftdi, 115200), sphere monitor's last 2 s: median {shown['p50']:.2f} ms, p95 "
              f"{shown['p95']:.2f} ms; the board's truth: median {truth['p50']:.2f} ms, p95 {truth['p95']:.2f} ms "
              f"({truth['n']} samples); monitor - truth: {diff['p50']:+.2f} / {diff['p95']:+.2f} ms")


#: the figures --against puts side by side: (stage, percentile)
COMPARED = (("total", "p50"), ("total", "p95"), ("host", "p50"), ("host", "p95"), ("host", "p99"))


def side_by_side(rows, against: str) -> None:
    """Each row's figures of this tree over REV's (below 1: this tree is faster)."""
    print(f"this tree / {against} (the same rows, the same run):")
    print(f"  {'adapter':<10} {'baud':>7} " + " ".join(f"{stage + ' ' + p:>16}" for stage, p in COMPARED))
    other = {(r["row"], r["baud"]): r for r in rows if _tree(r) == against}
    for r in rows:
        o = other.get((r["row"], r["baud"]))
        if _tree(r) != THIS or o is None:
            continue
        cells = []
        for stage, p in COMPARED:
            a, b = r["stages_ms"][stage].get(p), o["stages_ms"][stage].get(p)
            cells.append(f"{a:5.2f}/{b:5.2f} {a / b:4.2f}" if a is not None and b else f"{'-':>16}")
        print(f"  {r['row']:<10} {r['baud']:>7} " + " ".join(f"{c:>16}" for c in cells))
