"""The host stage's floor on this machine, for ``sphere bench latency``: the same path with none of the daemon's work.

A relay process, scheduled as sphere-mouse's loop asks to be (:class:`sphere.daemon.priority.LoopPriority`), waits
on a pty exactly as the serial source does (``select``, then one read of what has come) and answers each byte with
one relative XTest move through the daemon's own x11 backend (through libXtst or python-xlib: the two
libraries it can use); the bench's pointer watch (the same
:class:`~sphere.bench.latency.PointerRecorder` as the rows) sees the move. Bytes are written every few ms at random
phases, the time read before the write, as the virtual board stamps its writes. What this takes — the kernel
handing the pty's bytes to the reader, a wake-up, XTest, the X server, a wake-up of the watch — is what any daemon
pays on this machine before doing any work; the rows' host stage over it is what sphere-mouse adds.

``python -m sphere.bench._latency_floor PTY DISPLAY VIA`` is the relay (it runs until the pty closes).
"""

from __future__ import annotations

import os
import random
import select
import subprocess
import sys
import time
import tty

import numpy as np

from sphere.daemon.backends.x11 import X11Backend
from sphere.daemon.priority import LoopPriority, thread_scheduling


def relay(pty_path: str, display: str, via: str) -> int:
    LoopPriority().raise_()
    backend = X11Backend(display, via=via)
    fd = os.open(pty_path, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)
    print("ready", flush=True)
    step = 1
    try:
        while True:
            select.select([fd], [], [])
            try:
                data = os.read(fd, 4096)
            except OSError:  # the bench closed its side
                break
            if not data:
                break
            for _ in data:
                step = -step  # back and forth: the pointer never reaches the screen's edge
                backend.move(step, 0)
    finally:
        backend.close()
    return 0


def measure(display: str, recorder_factory, writes: int = 1000, via: str = "libXtst", period_s: float = 0.005,
            seed: int = 3) -> dict:
    """``writes`` one-byte writes to the relay's pty (its moves through ``via``), each followed by its move: the
    write → move time of each (``ms``), and how the relay was scheduled. ``recorder_factory(display)`` gives a
    started pointer watch with ``changes`` (monotonic ns, x, y) and ``stop``."""
    master, slave = os.openpty()
    tty.setraw(master)
    path = os.ttyname(slave)
    proc = subprocess.Popen([sys.executable, "-P", "-m", "sphere.bench._latency_floor", path, display, via],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    recorder = None
    try:
        line = proc.stdout.readline()
        if line.strip() != "ready":
            raise RuntimeError("the host floor's relay did not start: " + (line + proc.stderr.read()).strip()[-300:])
        scheduling = thread_scheduling(proc.pid)
        recorder = recorder_factory(display)
        time.sleep(0.1)
        rng = random.Random(seed)
        sent = np.empty(writes, dtype=np.int64)
        for k in range(writes):
            time.sleep(period_s * (0.5 + rng.random()))
            sent[k] = time.monotonic_ns()
            os.write(master, b"x")
        time.sleep(0.1)
    finally:
        if recorder is not None:
            recorder.stop.set()
            recorder.join(5)
        os.close(master)
        os.close(slave)
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            proc.kill()
    moves = recorder.changes[1:-1, 0]  # between the first and the last entry: the start and end positions
    i = np.searchsorted(moves, sent, side="right")
    ok = i < len(moves)
    return {"writes": writes, "moves": int(len(moves)), "via": via, "relay_scheduling": scheduling,
            "ms": ((moves[i[ok]] - sent[ok]) / 1e6).tolist()}


if __name__ == "__main__":
    sys.exit(relay(sys.argv[1], sys.argv[2], sys.argv[3]))
