"""The scheduling priority of the daemon's loop (the port → pointer path), asked of the OS where it allows it.

On a machine whose cores are busy, a frame that has arrived waits for a core: ``sphere bench latency`` saw the
host stage's p99 (the frame in the port → the X pointer moved) go from 1.3 ms to 4.8 ms at the same load only
because the whole bench ran at nice 0 instead of nice −5. Audio servers (PipeWire, JACK) and input daemons do
what this module does: the one thread that moves data asks for real-time scheduling at a low priority.

:meth:`LoopPriority.raise_` runs in the thread of the loop (:meth:`sphere.daemon.app.SphereMouse.run`):

1. ``SCHED_FIFO`` at ``[priority] realtime`` (5 by default, below PipeWire's and JACK's data threads), if the
   process may: ``CAP_SYS_NICE``, or an ``RLIMIT_RTPRIO`` of at least that (host/packaging/sphere-mouse-limits.conf;
   a hard limit above the soft one is used: the soft limit is raised to it first). Only in the main thread, where
   the runaway guard can be installed (below).
2. Else a lower nice value (``[priority] nice``, −10), if ``CAP_SYS_NICE`` or ``RLIMIT_NICE`` allows it.
3. Else nothing changes: the daemon runs as before, and says so once at ``-v``.

Only the calling thread is raised (Linux keeps the policy and the nice value per thread); threads and processes
it starts later get normal scheduling (``SCHED_RESET_ON_FORK``): the 3-D page's server, a camera, the virtual
board of ``--simulate``.

**No busy loop can starve the machine.** Before it asks for real time the loop sets ``RLIMIT_RTTIME``
(``[priority] runaway_ms``, 200 ms): if the real-time thread ever computes that long without waiting (the loop
waits in ``select`` for the port 200 times a second and needs well under 1 ms per frame), the kernel sends
SIGXCPU, whose handler here puts the thread back to normal scheduling; the loop then logs a warning once. Should
even the handler not run (a thread stuck in C holding the interpreter), the kernel ends the process at the hard
limit (5 × that; the systemd unit restarts it). The kernel's own real-time throttling (``sched_rt_runtime_us``,
95 % of each second by default) is a further floor, and ``SCHED_FIFO`` at priority 5 leaves every other
core to the desktop.
"""

from __future__ import annotations

import os
import resource
import signal
import sys
import threading

from sphere.settings import Param, resolve

#: policy names as ``sphere bench latency`` and ``--print-stats`` print them
POLICY_NAMES = {0: "SCHED_OTHER", 1: "SCHED_FIFO", 2: "SCHED_RR", 3: "SCHED_BATCH", 5: "SCHED_IDLE"}
#: the kernel ends a real-time thread at this many times [priority] runaway_ms of CPU without a wait
HARD_RUNAWAY_FACTOR = 5


def describe(policy: int, rt_priority: int, nice: int) -> str:
    """``SCHED_FIFO 5``, ``SCHED_OTHER nice -10``: how a thread is scheduled, the way this module reports it."""
    name = POLICY_NAMES.get(policy, f"policy {policy}")
    return f"{name} {rt_priority}" if policy in (1, 2) else f"{name} nice {nice}"


def thread_scheduling(pid: int, tid: int | None = None) -> str:
    """How thread ``tid`` of process ``pid`` (its main thread if None) is scheduled, read from
    ``/proc/PID/task/TID/stat`` (what the kernel applies, not what was asked); ``unknown`` where there is no /proc."""
    path = f"/proc/{pid}/task/{pid if tid is None else tid}/stat"
    try:
        with open(path) as f:
            text = f.read()
    except OSError:
        return "unknown"
    fields = text[text.rindex(")") + 2:].split()  # after "pid (comm) ": field 3 (state) is fields[0]
    nice, rt_priority, policy = int(fields[16]), int(fields[37]), int(fields[38])  # stat fields 19, 40, 41
    return describe(policy & 0xFF, rt_priority, nice)


class LoopPriority:
    """Raises the calling thread's scheduling priority as far as the OS allows (:meth:`raise_`) and gives the
    old one back (:meth:`restore`). :attr:`granted` says what was got, :attr:`refused` why not, if so."""

    NAME = "priority"
    PARAMS = {
        "enabled": Param(True, doc="ask the OS for a higher scheduling priority for the loop that reads the port "
                                   "and moves the pointer: real time, else a lower nice value; where the system does "
                                   "not allow it nothing changes (said once at -v). host/docs/sphere-mouse.md, "
                                   "\"Scheduling priority\", says how to allow it"),
        "realtime": Param(5, "", 0, 99, "the SCHED_FIFO priority asked for (1-99; low, below audio servers' data "
                                        "threads); 0 = never real time", integer=True),
        "nice": Param(-10, "", -20, 0, "the nice value asked for when real time is not allowed (0 = none)",
                      integer=True),
        "runaway_ms": Param(200, "ms", 10, 5000, "a real-time loop that computes this long without waiting for the "
                                                 "port goes back to normal scheduling (RLIMIT_RTTIME)", integer=True),
    }

    def __init__(self, *args, **kwargs):
        p = resolve(self.PARAMS, args, kwargs)
        self.enabled = p["enabled"]
        self.realtime = p["realtime"]
        self.nice = p["nice"]
        self.runaway_ms = p["runaway_ms"]
        self.granted = "not asked"  # describe() of what the thread got (sphere-mouse --print-stats says it)
        self.refused = None  # why the priority was not raised (for the -v line), or None
        self.demoted = False  # the runaway guard fired
        self.on_demoted = None  # called (from the signal handler: it must only set a flag) when the guard fires
        self._tid = None
        self._saved = None  # (policy, param, nice) before raise_()
        self._old_handler = None

    # ------------------------------------------------------------------ asking

    def raise_(self) -> str:
        """Ask for real time, else a lower nice value, for the calling thread; returns :attr:`granted`."""
        if not self.enabled:
            self.granted = "not asked ([priority] enabled = false)"
            return self.granted
        if not hasattr(os, "sched_setscheduler") or not sys.platform.startswith("linux"):
            self.refused = "scheduling priority: not raised: only Linux is supported"
            self.granted = "unchanged"
            return self.granted
        self._tid = threading.get_native_id()
        self._saved = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority,
                       os.getpriority(os.PRIO_PROCESS, self._tid))
        why = []
        policy, rt_priority, nice = self._saved
        if policy in (os.SCHED_FIFO, os.SCHED_RR) and rt_priority >= self.realtime:
            self._saved = None  # started in real time already (chrt): left as it is
            self.granted = describe(policy, rt_priority, nice)
            return self.granted
        if self.realtime and self._realtime(why):
            self.granted = describe(os.SCHED_FIFO, self.realtime, nice)
        elif self.nice < nice and self._nice(why):
            self.granted = describe(os.SCHED_OTHER, 0, self.nice)
        else:
            self.granted = describe(policy, rt_priority, nice)
        if why and self.granted == describe(*self._saved):
            self.refused = ("scheduling priority: not raised (" + "; ".join(why) + "): the loop runs at normal "
                            "priority; host/docs/sphere-mouse.md, \"Scheduling priority\", says how to allow it")
        elif why:
            self.refused = f"scheduling priority: {self.granted} (" + "; ".join(why) + ")"
        return self.granted

    def _realtime(self, why: list) -> bool:
        if threading.current_thread() is not threading.main_thread():
            why.append("real time only in the main thread, where its runaway guard runs")
            return False
        _raise_soft_limit(resource.RLIMIT_RTPRIO, self.realtime)
        soft = self.runaway_ms * 1000
        try:
            _, hard_now = resource.getrlimit(resource.RLIMIT_RTTIME)
            hard = soft * HARD_RUNAWAY_FACTOR
            if hard_now != resource.RLIM_INFINITY:
                hard = min(hard, hard_now)
            resource.setrlimit(resource.RLIMIT_RTTIME, (min(soft, hard), hard))
        except (OSError, ValueError) as e:
            why.append(f"no runaway guard (RLIMIT_RTTIME: {e})")
            return False
        self._old_handler = signal.signal(signal.SIGXCPU, self._runaway)
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(self.realtime))
            return True
        except OSError as e:
            signal.signal(signal.SIGXCPU, self._old_handler)
            self._old_handler = None
            why.append(f"SCHED_FIFO {self.realtime}: {e.strerror or e} (needs CAP_SYS_NICE or RLIMIT_RTPRIO >= "
                       f"{self.realtime})")
            return False

    def _nice(self, why: list) -> bool:
        _raise_soft_limit(resource.RLIMIT_NICE, 20 - self.nice)  # the limit is 20 - the lowest nice allowed
        try:  # later threads and children start at nice 0 (set while the policy is normal: allowed to anyone)
            os.sched_setscheduler(0, os.SCHED_OTHER | os.SCHED_RESET_ON_FORK, os.sched_param(0))
        except OSError:
            pass
        try:
            os.setpriority(os.PRIO_PROCESS, self._tid, self.nice)
            return True
        except OSError as e:
            why.append(f"nice {self.nice}: {e.strerror or e} (needs CAP_SYS_NICE or RLIMIT_NICE >= {20 - self.nice})")
            return False

    # ------------------------------------------------------------------ the guard, giving back

    def _runaway(self, signum, frame) -> None:
        """SIGXCPU: the real-time thread computed ``runaway_ms`` without a wait. Back to normal scheduling (a
        system call on the thread's id: allowed to anyone, from any thread); the loop logs it (``on_demoted``)."""
        if self._tid is None or self.demoted:
            return
        try:
            os.sched_setscheduler(self._tid, os.SCHED_OTHER | os.SCHED_RESET_ON_FORK, os.sched_param(0))
        except OSError:
            return
        self.demoted = True
        self.granted = describe(os.SCHED_OTHER, 0, os.getpriority(os.PRIO_PROCESS, self._tid))
        if self.on_demoted is not None:
            self.on_demoted()

    def runaway_message(self) -> str:
        return (f"the port -> pointer loop computed {self.runaway_ms} ms without waiting for the port while it ran "
                f"in real time: it runs at normal priority from now on (please report this)")

    def restore(self) -> None:
        """The thread's scheduling as it was before :meth:`raise_` (always allowed: it lowers the priority)."""
        if self._saved is None:
            return
        policy, rt_priority, nice = self._saved
        self._saved = None
        try:
            os.sched_setscheduler(0, policy, os.sched_param(rt_priority))
        except OSError:  # clearing SCHED_RESET_ON_FORK needs the privilege: keep it, the rest as before
            try:
                os.sched_setscheduler(0, policy | os.SCHED_RESET_ON_FORK, os.sched_param(rt_priority))
            except OSError:
                pass
        try:
            os.setpriority(os.PRIO_PROCESS, self._tid, nice)
        except OSError:
            pass
        if self._old_handler is not None:
            signal.signal(signal.SIGXCPU, self._old_handler)
            self._old_handler = None


def _raise_soft_limit(which: int, wanted: int) -> None:
    """The soft limit up to ``wanted`` where the hard limit allows (an unprivileged process may; limits.conf's
    ``-`` sets both, ``hard`` only the ceiling)."""
    try:
        soft, hard = resource.getrlimit(which)
        if soft != resource.RLIM_INFINITY and soft < wanted:
            top = wanted if hard == resource.RLIM_INFINITY else min(wanted, hard)
            if top > soft:
                resource.setrlimit(which, (top, hard))
    except (OSError, ValueError):
        pass
