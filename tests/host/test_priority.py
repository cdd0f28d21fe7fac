"""The daemon loop's scheduling priority (sphere.daemon.priority): real time where allowed, else a lower nice
value, else nothing changes; never for a replay; a runaway real-time loop is put back by the kernel's SIGXCPU."""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import textwrap
import threading

import pytest

from sphere.daemon import priority as P
from sphere.daemon.app import SphereMouse
from sphere.daemon.backends.memory import RecordingBackend
from sphere.daemon.config import Config

LINUX = sys.platform.startswith("linux")


def test_thread_scheduling_reads_what_the_kernel_applies():
    assert P.thread_scheduling(os.getpid()) == P.describe(os.sched_getscheduler(0), os.sched_getparam(0).sched_priority,
                                                          os.getpriority(os.PRIO_PROCESS, threading.get_native_id()))
    assert P.thread_scheduling(2 ** 22 + 12345) == "unknown"
    assert P.describe(1, 5, 0) == "SCHED_FIFO 5" and P.describe(0, 0, -10) == "SCHED_OTHER nice -10"


@pytest.mark.skipif(not LINUX, reason="Linux scheduling")
def test_refused_everywhere_changes_nothing_and_says_why(monkeypatch):
    """Without CAP_SYS_NICE and without limits: the thread stays as it was, and the -v line names both refusals and
    where the docs say how to allow them."""
    before = P.thread_scheduling(os.getpid(), threading.get_native_id())

    def refuse(*a):
        raise PermissionError(1, "Operation not permitted")

    def not_other(pid, policy, param):  # SCHED_OTHER with reset-on-fork is allowed to anyone, the rest refused
        if policy & 0xFF != os.SCHED_OTHER:
            refuse()

    monkeypatch.setattr(os, "sched_setscheduler", not_other)
    monkeypatch.setattr(os, "setpriority", refuse)
    p = P.LoopPriority()
    got = p.raise_()
    p.restore()
    assert got == before
    assert "not raised" in p.refused and "SCHED_FIFO 5" in p.refused and "nice -10" in p.refused
    assert "RLIMIT_RTPRIO" in p.refused and "Scheduling priority" in p.refused
    assert P.thread_scheduling(os.getpid(), threading.get_native_id()) == before


def test_switched_off_asks_for_nothing(monkeypatch):
    monkeypatch.setattr(os, "sched_setscheduler", lambda *a: pytest.fail("asked although switched off"))
    p = P.LoopPriority(enabled=False)
    assert p.raise_().startswith("not asked") and p.refused is None


@pytest.mark.skipif(not LINUX, reason="Linux scheduling")
def test_a_soft_limit_is_raised_to_what_the_hard_limit_allows(monkeypatch):
    """limits.conf's `hard rtprio 10` leaves the soft limit at 0: the process may raise it itself."""
    calls = []
    monkeypatch.setattr(resource, "getrlimit", lambda which: (0, 10))
    monkeypatch.setattr(resource, "setrlimit", lambda which, lim: calls.append((which, lim)))
    P._raise_soft_limit(resource.RLIMIT_RTPRIO, 5)
    P._raise_soft_limit(resource.RLIMIT_NICE, 30)
    assert calls == [(resource.RLIMIT_RTPRIO, (5, 10)), (resource.RLIMIT_NICE, (10, 10))]


@pytest.mark.skipif(not LINUX, reason="Linux scheduling")
def test_outside_the_main_thread_never_real_time():
    """Real time needs the runaway guard's SIGXCPU handler, which only the main thread can install: another thread
    gets the nice value at most, and gets back what it had."""
    out = {}

    def loop():
        out["before"] = P.thread_scheduling(os.getpid(), threading.get_native_id())
        p = P.LoopPriority()
        out["granted"] = p.raise_()
        out["during"] = P.thread_scheduling(os.getpid(), threading.get_native_id())
        p.restore()
        out["after"] = P.thread_scheduling(os.getpid(), threading.get_native_id())

    t = threading.Thread(target=loop)
    t.start()
    t.join(10)
    assert not out["granted"].startswith("SCHED_FIFO")
    assert out["during"] == out["granted"]
    assert out["after"] == out["before"]


def test_a_replay_is_never_raised(tmp_path):
    """A replay at --speed 0 computes without a pause: the loop must not ask for real time for it."""
    from pathlib import Path

    from sphere.daemon.sources.replay import ReplaySource

    capture = Path(__file__).resolve().parents[1] / "captures" / "sim_turn_90.bin"
    cfg = Config()
    d = SphereMouse(cfg, ReplaySource(capture, speed=0), RecordingBackend(), log=lambda m: None)
    d.priority.raise_ = lambda: pytest.fail("a replay asked for a priority")
    d.run()
    assert d.priority.granted == "not asked (the source is not paced by a device)"


RUNAWAY = textwrap.dedent("""
    import os, sys, time
    from sphere.daemon.priority import LoopPriority, thread_scheduling
    p = LoopPriority(runaway_ms=50)
    got = p.raise_()
    if not got.startswith("SCHED_FIFO"):
        print("refused", got, p.refused)
        sys.exit(0)
    t0 = time.process_time()
    while not p.demoted and time.process_time() - t0 < 5.0:  # a busy loop in real time
        pass
    print("demoted" if p.demoted else "still", round(time.process_time() - t0, 3), thread_scheduling(os.getpid()))
""")


@pytest.mark.skipif(not LINUX, reason="Linux scheduling")
def test_a_busy_loop_in_real_time_is_put_back_to_normal_scheduling():
    """The runaway guard: a real-time loop that computes [priority] runaway_ms without waiting gets SIGXCPU
    (RLIMIT_RTTIME) and is back at normal scheduling, alive, after about that much CPU time."""
    r = subprocess.run([sys.executable, "-c", RUNAWAY], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    if r.stdout.startswith("refused"):
        pytest.skip(f"[optional] this process may not run in real time: {r.stdout.strip()}")
    word, cpu_s, scheduling = r.stdout.split(maxsplit=2)
    assert word == "demoted", r.stdout
    assert 0.04 <= float(cpu_s) < 1.0, r.stdout  # the soft limit (50 ms), not the hard one (the kernel's SIGKILL)
    assert scheduling.startswith("SCHED_OTHER nice "), r.stdout
