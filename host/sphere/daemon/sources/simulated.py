"""``--simulate``: the virtual board (``sphere sim --pty``) read through its pty like a real port.

The board is a child of the daemon that dies with it, even when the daemon is killed with SIGKILL:
the child asks the kernel for SIGTERM when its parent goes (``PR_SET_PDEATHSIG``), and the board
itself stops when its own parent is gone.
"""

from __future__ import annotations

import collections
import ctypes
import importlib.util
import os
import re
import signal
import subprocess
import sys
import threading
import time

from sphere.broad import BroadMissing, find_trial
from sphere.daemon.sources.base import SourceError, SourceFailed
from sphere.daemon.sources.scripted import ScriptedSource
from sphere.daemon.sources.serial import SerialSource, device_settings, serial_timing
from sphere.settings import Param, Settings
from sphere.sim import trace as T

PTY_RE = re.compile(r"(/dev/pts/\d+)")
#: what --simulate plays when no trace is named: the tour shows the product (pointer, clicks, the three modes)
DEFAULT_SIM_TRACE = "synthetic:tour"
PR_SET_PDEATHSIG = 1


def simulator_available() -> bool:
    try:
        return importlib.util.find_spec("sphere.commands.sim") is not None
    except Exception:
        return False


def simulator_command(trace: str = "", seconds: float = 600.0, extra=()) -> list[str]:
    """How --simulate starts the virtual board: ``sphere sim --trace TRACE --pty --seconds S`` (and ``extra``
    flags of `sphere sim`, e.g. faults for a test)."""
    return [sys.executable, "-m", "sphere.cli", "sim", "--trace", trace or DEFAULT_SIM_TRACE, "--pty",
            "--seconds", f"{seconds:g}", *extra]


def die_with_parent() -> None:
    """In a child between fork and exec: SIGTERM when the parent dies (Linux; elsewhere nothing)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        pass


def start_simulator(trace: str = "", log=None, timeout_s: float = 120.0, seconds: float = 600.0, extra=(),
                    said=None):
    """Start the virtual board; returns (process, pty path). The board prints ``... UART on /dev/pts/N``;
    the rest of its output is read so that it never blocks on a full pipe, its last lines kept in ``said`` (a
    ``collections.deque`` with a maxlen) when given. The first start may build the firmware and the board
    (make), hence the long timeout."""
    cmd = simulator_command(trace, seconds, extra)
    parent = os.getpid()

    def child_setup():
        die_with_parent()
        if os.getppid() != parent:  # the parent died before prctl took effect
            os._exit(1)

    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            preexec_fn=child_setup if sys.platform.startswith("linux") else None)
    deadline = time.monotonic() + timeout_s
    tail: list[str] = []
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            if proc.poll() is not None:
                break
            continue
        tail = (tail + [line.rstrip()])[-8:]
        if log and line.startswith("sphere: "):  # what `sphere sim` says of its first use (building the board)
            log(line.rstrip()[len("sphere: "):])
        m = PTY_RE.search(line)
        if m and os.path.exists(m.group(1)):
            keep = said if said is not None else collections.deque(maxlen=1)
            threading.Thread(target=lambda: keep.extend(line.rstrip() for line in proc.stdout), daemon=True).start()
            return proc, m.group(1)
    if proc.poll() is None:
        proc.kill()
    raise SourceError(f"`sphere {' '.join(cmd[3:])}` did not open its pty: " + " | ".join(tail[-4:]))


def trace_problem(trace: str) -> str | None:
    """Why `sphere sim` could not play ``trace`` ([source.simulate] trace), or None: checked before the board
    starts, so a typo is one clear line, not a fallback to the scripted sphere."""
    if not trace:
        return None
    if trace.endswith(".bin"):
        return None if os.path.isfile(trace) else f"--trace {trace}: no such trace file"
    if trace.startswith("synthetic:") or trace in T.SYNTHETIC:
        name = trace.split(":", 2)[1] if trace.startswith("synthetic:") else trace
        return None if name in T.SYNTHETIC else (f"--trace {trace}: no synthetic motion {name!r}; one of "
                                                  f"{', '.join(T.SYNTHETIC)}")
    try:
        find_trial(trace)
    except BroadMissing as e:
        return f"--trace: {e}"
    return None


class SimulatorRefused(SourceError):
    """The trace the user named cannot be played: said at once, no fallback to the scripted sphere."""


class SimulatorSource(SerialSource):
    """The virtual board's UART through the pty that `sphere sim --pty` exposes."""

    NAME = "simulate"
    PARAMS = {
        "seconds": Param(600.0, doc="how long the virtual board runs with `--simulate` (the daemon ends with it)",
                         lo=1.0, hi=86400.0),
        "trace": Param("", doc="motion the virtual board plays with `--simulate` (`--trace`): a BROAD trial (.mat, "
                               "name or number) or `synthetic:NAME` (see `sphere sim --help`); empty = the "
                               "tour, `synthetic:tour`"),
    }

    def __init__(self, trace: str = "", log=None, seconds: float = 600.0, **serial_kwargs):
        if log:  # said before the board's first start, which prepares the motion and may build the board
            log(f"simulated sphere: starting the virtual board with {trace} ({seconds:g} s)" if trace else
                f"simulated sphere: no trace named, playing the tour ({DEFAULT_SIM_TRACE}: the pointer, a click, "
                f"a double click, tosses through tilt and 3-D mode; --trace to choose another), {seconds:g} s")
        self.seconds = seconds
        self.said = collections.deque(maxlen=8)  # `sphere sim`'s last lines (why its board ended)
        self.proc, path = start_simulator(trace, log, seconds=seconds, said=self.said)
        serial_kwargs.setdefault("reset_on_open", False)
        super().__init__(port=path, log=log, **serial_kwargs)
        self.allow_pids = (self.proc.pid,)  # the board holds its own pty
        self.state = f"simulated sphere on {path}"

    @classmethod
    def from_settings(cls, s, log=None, cfg=None):
        """The virtual board when it can run here, else the built-in scripted sphere (said in the log). The
        link's timing is the serial source's ([source.serial])."""
        log = log or (lambda m: None)
        problem = trace_problem(s.trace)
        if problem:
            raise SimulatorRefused(problem)
        serial = cfg["source.serial"] if cfg is not None else Settings(SerialSource.PARAMS)
        if simulator_available():
            try:
                return cls(s.trace, log=log, seconds=s.seconds, device_settings=device_settings(cfg),
                           **serial_timing(serial, cfg))
            except SourceError as e:
                log(f"the virtual board cannot run here ({e}); using the built-in scripted sphere")
        else:
            log("the virtual board (sphere sim) is not installed here; using the built-in scripted sphere")
        scripted = cfg["source.scripted"] if cfg is not None else Settings(ScriptedSource.PARAMS)
        return ScriptedSource.from_settings(scripted, log, cfg)

    def _lose(self, why: str) -> None:
        # the pty closes when the board's simulated seconds are over and `sphere sim` exits right after:
        # that is the end of the run, not a lost link to look for again
        try:
            self.proc.wait(2.0)
        except subprocess.TimeoutExpired:
            super()._lose(why)
            return
        self._close()

    def _over(self) -> bool:
        if self.proc.poll() is None:
            return False
        rc = self.proc.returncode
        if rc != 0:  # killed, crashed: a failed run (exit 1), in the simulator's own words where it gave them
            why = next((line.rstrip(": ") for line in reversed(self.said) if line.startswith("sphere sim: ")),
                       f"`sphere sim` killed by {signal.Signals(-rc).name}" if -rc in signal.valid_signals()
                       else f"`sphere sim` exit status {rc}")
            raise SourceFailed(f"the simulated sphere stopped before its {self.seconds:g} s were over ({why}); "
                               "sphere-mouse stops with it: start it again")
        self.log("the simulated sphere's run is over")
        return True

    def close(self):
        super().close()
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
