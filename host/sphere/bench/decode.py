"""Decoder throughput: decoded frames per second on one core, against the device's frame rate.

    sphere bench decode [--seconds 60] [--repeat 5] [--json OUT]
    sphere bench decode --against REV [--pairs 3]   # beside the decoder of another revision of this repository

``--against`` measures both trees the same way, each run in a fresh process (this file, with that tree's
``sphere`` imported), the two sides taking turns, and prints the medians side by side with their ratios.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
import tempfile
import time

from sphere import argtypes
from sphere.protocol import FrameDecoder, encode_frame
from sphere.protocol.packets import Orientation, RawSample, Status

HELP = "decoded frames per second on one core (target: 200× the device's highest frame rate)"

#: The highest frame rate the device sends: raw 200 Hz + orientation 200 Hz + status 1 Hz.
DEVICE_MAX_FRAMES_PER_S = 401
#: --seconds' limit: an hour of stream (35 MB, built in memory); the device's 32-bit µs clock wraps at 4295 s
MAX_SECONDS = 3600.0


def add_arguments(p) -> None:
    p.add_argument("--seconds", type=argtypes.seconds_up_to(MAX_SECONDS), default=60.0,
                   help=f"simulated seconds of stream to decode (default 60, at most {MAX_SECONDS:g})")
    p.add_argument("--repeat", type=argtypes.at_least_one, default=5, help="timed repetitions; the median is reported")
    p.add_argument("--json", metavar="OUT", type=argtypes.out_file, help="also write the figures as JSON")
    p.add_argument("--against", metavar="REV", help="side by side with the decoder of this git revision of the "
                   "repository (runs in fresh processes taking turns; ratios printed)")
    p.add_argument("--pairs", type=argtypes.at_least_one, default=3, help="with --against: runs of each side "
                   "(default 3)")


def make_stream(seconds: float, seed: int = 1) -> tuple[bytes, int]:
    """Raw 200 Hz + orientation 200 Hz + status 1 Hz, as the device would send them."""
    rng = random.Random(seed)
    frames = []
    seq = 0
    for i in range(int(seconds * 200)):
        t = i * 5000
        a = tuple(rng.randint(-300, 300) for _ in range(3))
        frames.append(encode_frame(RawSample(t, 15, a, (rng.randint(-2000, 2000), 3, -4), (200, -40, -380)), seq))
        frames.append(encode_frame(Orientation(t, 1, (16000, 1000, -2000, 3000)), seq + 1))
        seq = (seq + 2) & 0xFF
        if i % 200 == 0:
            frames.append(encode_frame(Status(t, 7, (0, 0, 0), 0, 0, 0, 0, 7, 0, 400, 0), seq))
            seq = (seq + 1) & 0xFF
    return b"".join(frames), len(frames)


class NothingDecoder:
    """A decoder that does nothing: what the same loop costs with a Python method call per feed and no work in
    it, the ceiling of any decoder written in Python fed a byte at a time on this interpreter and machine."""

    __slots__ = ()

    def feed(self, data: bytes) -> list:
        return []


def _frames_per_s(make, data: bytes, n: int, chunk: int, repeat: int, expect: int) -> float:
    times = []
    for _ in range(repeat):
        pieces = [data[i : i + chunk] for i in range(0, len(data), chunk)]
        decoder = make()
        t0 = time.process_time()  # this process's CPU time: the figure is per core, whatever else runs
        got = 0
        for piece in pieces:
            got += len(decoder.feed(piece))
        times.append(time.process_time() - t0)
        assert got == expect
    times.sort()
    return n / times[len(times) // 2]


#: the feed sizes measured (bytes per call; 0 = the whole stream in one call)
FEEDS = (1, 64, 4096, 0)


def measure(seconds: float, repeat: int) -> dict:
    """Frames per second for each feed size, and for a method that does nothing fed a byte at a time."""
    data, n = make_stream(seconds)
    rates = {chunk: _frames_per_s(FrameDecoder, data, n, chunk or len(data), repeat, n) for chunk in FEEDS}
    return {"frames": n, "bytes": len(data), "frames_per_s": {str(k): v for k, v in rates.items()},
            "empty_method_byte_fed_frames_per_s": _frames_per_s(NothingDecoder, data, n, 1, repeat, 0),
            "device_max_frames_per_s": DEVICE_MAX_FRAMES_PER_S}


def _label(chunk: str) -> str:
    return "whole stream" if chunk == "0" else chunk


def _side(host_dir: str, args) -> dict:
    """One :func:`measure` in a fresh process with ``host_dir``'s ``sphere`` imported (this file run as a script)."""
    env = dict(os.environ, PYTHONPATH=host_dir)
    cmd = [sys.executable, "-P", os.path.abspath(__file__), str(args.seconds), str(args.repeat)]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"the run with {host_dir} failed: {out.stderr.strip()[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def against(args) -> int:
    from sphere.bench._revision import medians, take_turns, tree_of  # --against: not in the older sphere a side runs with

    here = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # .../host
    this = "this tree"
    with tempfile.TemporaryDirectory(prefix="sphere-bench-") as tmp:
        runs = take_turns({this: here, args.against: tree_of(args.against, tmp)}, args.pairs,
                          lambda name, host_dir: _side(host_dir, args),
                          lambda r: ", ".join(f"{_label(k)}{' B' if k != '0' else ''} {v:,.0f}"
                                              for k, v in r["frames_per_s"].items())
                          + f" frames/s; empty method {r['empty_method_byte_fed_frames_per_s']:,.0f}")
    print(f"medians of {args.pairs} runs each (each the median of {args.repeat}), frames/s by this process's CPU "
          f"time, this tree beside {args.against}; load average after {os.getloadavg()[0]:.2f}:")
    print(f"{'feed size (bytes)':>18} {'this tree':>12} {args.against:>12} {'ratio':>7}")
    keys = [(k, _label(k)) for k in runs[this][0]["frames_per_s"]]
    rows = [(lambda r, k=k: r["frames_per_s"][k], label) for k, label in keys]
    rows.append((lambda r: r["empty_method_byte_fed_frames_per_s"], "empty method, 1"))
    for get, label in rows:
        a, b, ratio = medians(runs, this, args.against, get)
        print(f"{label:>18} {a:12,.0f} {b:12,.0f} {ratio:7.2f}")
    return 0


def run(args) -> int:
    if args.against:
        from sphere.bench._revision import RevisionError  # --against: not in the older sphere a side runs with

        print(f"decoder throughput side by side: {args.seconds:g} s of the densest stream, {args.pairs} runs of each "
              f"side in fresh processes taking turns, {os.cpu_count()} CPUs, Python {sys.version.split()[0]}, "
              f"load average before {os.getloadavg()[0]:.2f}", flush=True)
        try:
            return against(args)
        except RevisionError as e:
            print(f"sphere bench decode: {e}", file=sys.stderr)
            return 2
    r = measure(args.seconds, args.repeat)
    n = r["frames"]
    print(f"decoder throughput, {n} frames ({r['bytes']} bytes, {args.seconds:g} s of the densest stream), "
          f"CPU time of this process, median of {args.repeat}; load average {os.getloadavg()[0]:.2f}")
    print(f"{'feed size (bytes)':>18} {'frames/s':>12} {'× device max (' + str(DEVICE_MAX_FRAMES_PER_S) + '/s)':>24}")
    for chunk, fps in r["frames_per_s"].items():
        print(f"{_label(chunk):>18} {fps:12.0f} {fps / DEVICE_MAX_FRAMES_PER_S:24.0f}")
    ceiling = r["empty_method_byte_fed_frames_per_s"]
    print(f"a Python method that does nothing, fed the same bytes one at a time: {ceiling:.0f} frames/s "
          f"({r['bytes'] / n:.1f} calls a frame; the byte-fed decoder reaches {r['frames_per_s']['1'] / ceiling:.2f} "
          "of it)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(r, f, indent=2)
    return 0


if __name__ == "__main__":  # one side of --against: python -P decode.py SECONDS REPEAT, with PYTHONPATH=<host>
    print(json.dumps(measure(float(sys.argv[1]), int(sys.argv[2]))))
