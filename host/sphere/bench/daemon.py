"""Latency and CPU benchmark of sphere-mouse's serial path (prints figures; not a unit test).

    python -m sphere.bench.daemon [--seconds 10] [--rate 200] [--json]
    python -m sphere.bench.daemon --against REV [--pairs 8] [--seconds 10]

1. **Latency**, in process: a writer process plays a sphere on a pty at ``--rate`` RAW_SAMPLE frames/s
   (a steady turn, so every sample moves the pointer); the daemon (SerialSource → SphereMouse) runs in
   another thread with a backend that notes ``time.perf_counter_ns()`` when it is called, with the
   settings a user has by default (the host's gyro-bias estimator on; the 3-D stream, a separate
   server, off). Reported: from the moment the frame's write into the pty began (the time is read just
   before the write: a daemon woken by it may finish before the writer runs again) to the backend call (p50,
   p99, max), and the part of it after the source's read returned (what the
   daemon's own work adds: decoding, duplicate check, bias, fusion filter, smoothing, the move).
   For comparison, the floor: the same pty path read by a bare ``select`` + ``os.read`` loop.
2. **CPU**, out of process: the real ``sphere-mouse --port PTY --backend log`` as a subprocess fed at
   the same rate; its CPU time over the run (the kernel's per-thread run time in /proc/PID/task/*/schedstat,
   nanoseconds; utime + stime in clock ticks where that is absent), as % of one core.
3. **Work per frame**, in process: decoding and ``SphereMouse.handle`` over 12,000 frames with no pty, CPU µs
   per frame (best of 3): what the daemon computes, without the wake-ups that dominate the CPU share
   (with the outputs the settings switch on, attached as sphere-mouse attaches them; no client connected).

``--against default`` runs this tree with the ``--set`` settings beside the same tree without them (what a
setting costs, say ``--set outputs.dsu.enabled=true``), the same way.

``--against REV`` runs the daemon of another revision of this repository (say the one an issue was filed
at) side by side with this one: ``git archive REV host`` into a temporary folder, then ``--pairs`` runs of
each, interleaved and in alternating order, every run a fresh process executing *this* file's
measurement with the other tree's ``sphere`` package on ``PYTHONPATH`` (so both are measured the same
way, with the same settings); it prints each side's medians and their ratios (this tree / REV).
"""

from __future__ import annotations

import argparse
import glob
import inspect
import json
import multiprocessing as mp
import os
import select
import subprocess
import sys
import tempfile
import threading
import time
import tty

try:
    from sphere.daemon.scripted_sphere import ScriptedSphere, hello_packet
except ImportError:  # --against a revision from before the module's rename (it was sphere.daemon.synthetic)
    from sphere.daemon.synthetic import ScriptedSphere, hello_packet
from sphere.daemon.app import SphereMouse
from sphere.daemon.backends.memory import RecordingBackend
from sphere.daemon.config import Config, ConfigError, parse_set
from sphere.daemon.sources.serial import SerialSource
from sphere.protocol import FrameDecoder


class PtySphere:
    """A sphere behind a pty, in its own process (so it never holds the daemon's GIL): answers GET_HELLO
    with HELLO, then writes one RAW_SAMPLE per period and notes when each one's write began.
    ``time.perf_counter_ns`` is CLOCK_MONOTONIC on Linux, the same clock in both processes."""

    def __init__(self, rate_hz: float, seconds: float, orientation: bool = False):
        ctx = mp.get_context("fork")
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.path = os.ttyname(slave)
        os.close(slave)
        self.rate_hz = rate_hz
        self.seconds = seconds
        self.orientation = orientation
        self.started = ctx.Event()
        self.done = ctx.Event()
        self._frames = ctx.Value("l", 0)
        self._results = ctx.Queue()
        self.written_ns: dict[int, int] = {}
        self.proc = ctx.Process(target=self._run, daemon=True)
        self.proc.start()
        os.close(self.master)  # the writer process has its own copy

    @property
    def frames(self) -> int:
        return self._frames.value

    def _run(self):
        sphere = ScriptedSphere(imu_rate_hz=int(self.rate_hz), orientation_every=2 if self.orientation else 10**9,
                                status_every_s=1.0)
        written = {}
        dec = FrameDecoder("host")
        while True:
            try:
                r, _, _ = select.select([self.master], [], [], 0.05)
                if r and any(p.NAME == "GET_HELLO" for p in dec.feed(os.read(self.master, 256))):
                    break
            except OSError:
                time.sleep(0.01)
        os.write(self.master, sphere.frame(hello_packet(int(self.rate_hz), 0)))
        self.started.set()
        period = 1.0 / self.rate_hz
        t_next = time.perf_counter() + 0.2
        for _ in range(int(self.seconds * self.rate_hz)):
            frames = sphere.sample((0.0, 8.0, 50.0))  # a steady turn: every sample moves the pointer
            wait = t_next - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            t_next += period
            # the time before the write: a daemon the write wakes may run its whole frame before this process gets
            # the core back (its loop at a raised priority: sphere.daemon.priority), and a time read after it
            # would leave that out (latencies below zero were seen)
            written[frames[0][0]] = time.perf_counter_ns()
            for _, f in frames:
                os.write(self.master, f)
            self._frames.value += len(frames)
        self._results.put(written)
        self.done.set()
        time.sleep(0.5)  # keep the pty open until the reader has drained it

    def wait(self, timeout: float) -> bool:
        if not self.done.wait(timeout):
            return False
        self.written_ns = self._results.get(timeout=5)
        return True

    def close(self):
        if self.proc.is_alive():
            self.proc.terminate()
        self.proc.join(5)


def percentile(sorted_values, p):
    if not sorted_values:
        return float("nan")
    k = min(len(sorted_values) - 1, max(0, int(round(p / 100.0 * (len(sorted_values) - 1)))))
    return sorted_values[k]


def latency(seconds: float, rate: float, orientation: bool, settings: dict | None = None):
    dev = PtySphere(rate, seconds, orientation)
    source = SerialSource(dev.path, hello_timeout_s=0.1, link_timeout_s=5.0)
    cfg = _config(settings)
    calls = []  # (device t_us being handled, call ns, source arrival ns)
    backend = RecordingBackend()
    daemon = SphereMouse(cfg, source, backend, log=lambda m: None)
    backend.on_call = lambda ns: calls.append((daemon.now_us, ns, source.arrival_ns))
    t = threading.Thread(target=daemon.run, daemon=True)
    t.start()
    dev.started.wait(10)
    wall0 = time.perf_counter()
    dev.wait(seconds + 10)
    time.sleep(0.2)
    wall = time.perf_counter() - wall0
    daemon.stop()
    t.join(5)
    dev.close()
    total = []
    after_read = []
    for t_us, call_ns, arrival_ns in calls:
        w = dev.written_ns.get(t_us)
        if w is None:
            continue
        total.append((call_ns - w) / 1000.0)
        after_read.append((call_ns - arrival_ns) / 1000.0)
    total.sort()
    after_read.sort()
    return {"frames": dev.frames, "calls": len(total), "wall_s": wall, "total": total, "after_read": after_read}


def baseline(seconds: float, rate: float):
    """The floor: the same pty, writer and rate, with a bare select + os.read loop instead of the daemon."""
    master, slave = os.openpty()
    tty.setraw(slave)
    frame = ScriptedSphere().sample((0.0, 0.0, 50.0))[0][1]
    written: list[int] = []
    got: list[int] = []
    stop = threading.Event()

    def reader():
        have = 0
        while not stop.is_set():
            r, _, _ = select.select([slave], [], [], 0.05)
            if r:
                have += len(os.read(slave, 4096))
                now = time.perf_counter_ns()
                while have >= len(frame):
                    have -= len(frame)
                    got.append(now)

    t = threading.Thread(target=reader, daemon=True)
    t.start()
    period = 1.0 / rate
    t_next = time.perf_counter() + 0.1
    for _ in range(int(seconds * rate)):
        wait = t_next - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        t_next += period
        written.append(time.perf_counter_ns())  # before the write, as PtySphere
        os.write(master, frame)
    time.sleep(0.1)
    stop.set()
    t.join(2)
    os.close(master)
    os.close(slave)
    return sorted((g - w) / 1000.0 for w, g in zip(written, got))


def task_cpu_ns(pid: int) -> dict | None:
    """Thread id → CPU nanoseconds it has run (schedstat), for the process's live threads; None without them."""
    out = {}
    try:
        for path in glob.glob(f"/proc/{pid}/task/*/schedstat"):
            with open(path) as f:
                out[path.split("/")[-2]] = int(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return None
    return out or None


def cpu_between(before: dict, after: dict) -> float:
    """CPU seconds the threads ran between two :func:`task_cpu_ns` readings: each live thread's own increase (a
    thread that ended in between takes its total with it, so a sum of the two readings could go down)."""
    return sum(ns - before.get(tid, 0) for tid, ns in after.items()) * 1e-9


def proc_cpu_s(pid: int) -> float:
    """CPU seconds the process's threads have run: schedstat's nanoseconds where the kernel keeps them (a
    10 s run at 2.5 % is 25 clock ticks, too coarse to compare two versions), else utime + stime."""
    tasks = task_cpu_ns(pid)
    if tasks is not None:
        return sum(tasks.values()) * 1e-9
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    ticks = os.sysconf("SC_CLK_TCK")
    return (int(fields[11]) + int(fields[12])) / ticks  # utime, stime


def cpu(seconds: float, rate: float, orientation: bool, set_items=()):
    dev = PtySphere(rate, seconds + 1.0, orientation)
    proc = subprocess.Popen([sys.executable, "-m", "sphere.mouse", "--port", dev.path, "--backend", "log",
                             "--no-stream", "--quiet", "--config", os.devnull]
                            + [a for item in set_items for a in ("--set", item)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        if not dev.started.wait(15):
            raise RuntimeError("sphere-mouse did not ask for HELLO")
        time.sleep(1.0)  # imports, discovery and warm-up are not the steady state
        t0, c0, w0 = task_cpu_ns(proc.pid), proc_cpu_s(proc.pid), time.perf_counter()
        f0 = dev.frames
        dev.wait(seconds + 10)
        t1, c1, w1 = task_cpu_ns(proc.pid), proc_cpu_s(proc.pid), time.perf_counter()
        f1 = dev.frames
        if t0 is not None and t1 is not None:  # per thread: a thread that ended does not take its past away
            c0, c1 = 0.0, cpu_between(t0, t1)
    finally:
        proc.terminate()
        proc.wait(10)
        dev.close()
    return {"cpu_pct": 100.0 * (c1 - c0) / (w1 - w0), "wall_s": w1 - w0, "fps": (f1 - f0) / (w1 - w0)}


def work_per_frame_us(frames: int = 12000, passes: int = 3, settings: dict | None = None) -> float:
    """CPU µs per frame of the daemon's own work, in this process with no pty and no other thread: decoding and
    ``SphereMouse.handle`` (deferred work included) over ``frames`` frames of the same steady turn, best of
    ``passes``. Far steadier than a process's CPU share, which the pty's wake-ups dominate."""
    try:
        from sphere.protocol import PacketStream  # --against: an older revision may lack it (see below)

        def stream():
            return PacketStream().feed
    except ImportError:  # a revision from before PacketStream (--against): its sources' own decoding
        from sphere.daemon.sources import _Decoding  # --against: that revision's own decoding

        def stream():
            return _Decoding().decode

    sphere = ScriptedSphere(imu_rate_hz=200, orientation_every=10**9, status_every_s=1.0)
    data = [sphere.frame(hello_packet(200, 0))] + [f for _ in range(frames) for _, f in sphere.sample((0.0, 8.0, 50.0))]
    cfg = _config(settings)

    class _NoSource:
        generation = 0

    # the outputs a --set switches on (the daemon's fan-out), as sphere-mouse attaches them
    try:
        from sphere.daemon.outputs.fanout import attach as _attach  # --against: an older revision may lack it
    except ImportError:
        try:
            from sphere.daemon.outputs import attach as _attach  # a revision from before issue 25 (--against)
        except ImportError:  # a revision from before the outputs
            _attach = None

    def attach(cfg):
        if _attach is None:
            return None
        # before the 3-D page was an output (--against), attach took the stream first
        return _attach(cfg) if "stream" not in inspect.signature(_attach).parameters else _attach(None, cfg)

    best = float("inf")
    for _ in range(passes):
        feed = stream()
        outputs = attach(cfg)
        daemon = SphereMouse(cfg, _NoSource(), RecordingBackend(), stream=outputs, log=lambda m: None)
        handle = daemon.handle
        c0 = time.process_time()
        for f in data:
            for dp in feed(f):
                handle(dp)
        best = min(best, (time.process_time() - c0) / len(data))
        if outputs is not None:
            outputs.stop()
    return 1e6 * best


def _settings(set_items) -> dict:
    """``--set`` items as a config override (checked against the daemon's config: a bad one is an error)."""
    settings = parse_set(list(set_items)) if set_items else {}
    if settings:
        Config().with_overrides(settings, "--set")
    return settings


def _config(settings: dict | None):
    """The daemon's default config with the 3-D stream (a separate server) off, and ``settings`` over it."""
    try:
        cfg = Config().with_overrides({"outputs.page": {"enabled": False}}, "bench")
    except ConfigError:  # a revision from before the 3-D page was an output (--against)
        cfg = Config().with_overrides({"stream": {"enabled": False}}, "bench")
    return cfg.with_overrides(settings, "--set") if settings else cfg


def measure(seconds: float, rate: float, orientation: bool, set_items=()) -> dict:
    settings = _settings(set_items)
    lat = latency(seconds, rate, orientation, settings)
    t, a = lat["total"], lat["after_read"]
    b = baseline(seconds, rate)
    c = cpu(seconds, rate, orientation, set_items)
    return {"calls": lat["calls"], "frames": lat["frames"],
            "p50_us": percentile(t, 50), "p99_us": percentile(t, 99), "max_us": max(t) if t else float("nan"),
            "after_read_p50_us": percentile(a, 50), "after_read_p99_us": percentile(a, 99),
            "floor_p50_us": percentile(b, 50), "floor_p99_us": percentile(b, 99),
            "cpu_pct": c["cpu_pct"], "cpu_wall_s": c["wall_s"], "fps": c["fps"], "work_us": work_per_frame_us(settings=settings)}


def report(r: dict) -> None:
    print(f"latency, write into the pty → backend call ({r['calls']} pointer moves of {r['frames']} frames):")
    print(f"  p50 {r['p50_us']:7.0f} µs   p99 {r['p99_us']:7.0f} µs   max {r['max_us']:7.0f} µs")
    print(f"  of which after the read returned: p50 {r['after_read_p50_us']:.0f} µs, p99 {r['after_read_p99_us']:.0f} µs")
    print(f"  floor on this machine now (same pty and writer, a bare os.read loop): p50 {r['floor_p50_us']:.0f} µs, "
          f"p99 {r['floor_p99_us']:.0f} µs")
    print(f"CPU of the sphere-mouse process (backend log, stdout to /dev/null) at {r['fps']:.0f} frames/s over "
          f"{r['cpu_wall_s']:.1f} s: {r['cpu_pct']:.2f} % of one core")
    print(f"the daemon's own work per frame (decoding and SphereMouse.handle in one process, no pty): "
          f"{r['work_us']:.1f} µs of CPU")
    print(f"load average after: {os.getloadavg()[0]:.2f} (other work on the machine shows in the latency tail)")
    target_ok = r["p99_us"] < 2000 and r["cpu_pct"] < 5.0
    print("targets (p99 < 2 ms, CPU < 5 % of one core): " + ("met" if target_ok else "NOT met"))


#: the figures the side-by-side table compares (key, label)
COMPARED = (("p50_us", "latency p50 µs"), ("p99_us", "latency p99 µs"),
            ("after_read_p50_us", "after the read p50 µs"), ("after_read_p99_us", "after the read p99 µs"),
            ("floor_p99_us", "pty floor p99 µs"), ("cpu_pct", "CPU % of one core"),
            ("work_us", "work per frame µs CPU"))


def run_side(host_dir: str, args, set_items=None) -> dict:
    """One measurement in a fresh process: this file, with ``host_dir``'s ``sphere`` package imported."""
    env = dict(os.environ, PYTHONPATH=host_dir)
    cmd = [sys.executable, "-P", os.path.abspath(__file__), "--json", "--seconds", str(args.seconds),
           "--rate", str(args.rate)] + (["--orientation"] if args.orientation else [])
    cmd += [a for item in (args.set if set_items is None else set_items) for a in ("--set", item)]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=args.seconds * 4 + 120)
    if out.returncode != 0:
        raise RuntimeError(f"the run with {host_dir} failed: {out.stderr.strip()[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


DEFAULT_SIDE = "default"


def against(args) -> int:
    from sphere.bench._revision import medians, take_turns, tree_of  # --against: not in the older sphere a side runs with

    here = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # .../host
    with tempfile.TemporaryDirectory(prefix="sphere-bench-") as tmp:
        # "default": this tree without the --set settings (what a setting, say an output switched on, costs)
        other = here if args.against == DEFAULT_SIDE else tree_of(args.against, tmp)
        runs = take_turns({"this": here, args.against: other}, args.pairs,
                          lambda name, host_dir: run_side(host_dir, args, [] if name == DEFAULT_SIDE else None),
                          lambda r: f"p50 {r['p50_us']:.0f} µs, p99 {r['p99_us']:.0f} µs, after read p50 "
                                    f"{r['after_read_p50_us']:.0f} / p99 {r['after_read_p99_us']:.0f} µs, CPU "
                                    f"{r['cpu_pct']:.2f} %, work {r['work_us']:.1f} µs/frame")
    print(f"medians of {args.pairs} runs each ({args.seconds:g} s per run), this tree beside {args.against}; "
          f"load average after {os.getloadavg()[0]:.2f}:")
    print(f"  {'':24} {'this tree':>10} {args.against:>12} {'ratio':>7}")
    for key, label in COMPARED:
        a, b, ratio = medians(runs, "this", args.against, lambda r: r[key])
        print(f"  {label:24} {a:10.2f} {b:12.2f} {ratio:7.2f}")
    return 0


HELP = "latency and CPU of sphere-mouse's serial path (also python -m sphere.bench.daemon)"


def add_arguments(ap) -> None:
    ap.add_argument("--seconds", type=float, default=10.0, help="length of each run (default 10)")
    ap.add_argument("--rate", type=float, default=200.0, help="RAW_SAMPLE frames per second (default 200)")
    ap.add_argument("--orientation", action="store_true", help="also send ORIENTATION at half the rate")
    ap.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    ap.add_argument("--against", metavar="REV", help="side by side with the daemon of this git revision, or "
                    "'default': this tree without the --set settings")
    ap.add_argument("--pairs", type=int, default=8, help="with --against: runs of each side (default 8)")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                    help="a daemon setting other than its default, as sphere-mouse's --set (repeatable), e.g. "
                         "--set gyro.auto_bias=false")


def run(args, prog: str = "sphere bench daemon") -> int:
    if not 0.5 <= args.seconds <= 3600 or not 1 <= args.rate <= 2000 or not 1 <= args.pairs <= 100:
        print(f"{prog}: --seconds must be 0.5–3600, --rate 1–2000, --pairs 1–100", file=sys.stderr)
        return 2
    try:
        _settings(args.set)
    except Exception as e:  # ConfigError: the same one line sphere-mouse gives
        print(f"{prog}: {e}", file=sys.stderr)
        return 2
    if args.against:
        print(f"sphere-mouse benchmark, side by side: {args.rate:g} RAW_SAMPLE frames/s, {args.seconds:g} s per run, "
              f"{os.cpu_count()} CPUs, Python {sys.version.split()[0]}, load average before {os.getloadavg()[0]:.2f}",
              flush=True)
        from sphere.bench._revision import RevisionError  # --against: not in the older sphere a side runs with

        try:
            return against(args)
        except RevisionError as e:
            print(f"{prog}: {e}", file=sys.stderr)
            return 2
    if not args.json:
        print(f"sphere-mouse benchmark: {args.rate:g} RAW_SAMPLE frames/s" + (" + ORIENTATION" if args.orientation else "")
              + f", {args.seconds:g} s per run, pty, {os.cpu_count()} CPUs, Python {sys.version.split()[0]}, "
              f"load average before {os.getloadavg()[0]:.2f}")
    r = measure(args.seconds, args.rate, args.orientation, args.set)
    if args.json:
        print(json.dumps(r))
    else:
        report(r)
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sphere.bench.daemon", description=__doc__.split("\n\n")[0])
    add_arguments(ap)
    return run(ap.parse_args(argv), prog="python -m sphere.bench.daemon")


if __name__ == "__main__":
    sys.exit(main())
