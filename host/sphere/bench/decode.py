"""Decoder throughput: decoded frames per second on one core, against the device's frame rate."""

from __future__ import annotations

import json
import random
import time

from sphere import argtypes
from sphere.protocol import FrameDecoder, encode_frame
from sphere.protocol.packets import Orientation, RawSample, Status

HELP = "decoded frames per second on one core (target: 200× the device's highest frame rate)"

#: The highest frame rate the device sends: raw 200 Hz + orientation 200 Hz + status 1 Hz.
DEVICE_MAX_FRAMES_PER_S = 401


def add_arguments(p) -> None:
    p.add_argument("--seconds", type=argtypes.seconds, default=60.0, help="simulated seconds of stream to decode (default 60)")
    p.add_argument("--repeat", type=argtypes.at_least_one, default=5, help="timed repetitions; the median is reported")
    p.add_argument("--json", metavar="OUT", type=argtypes.out_file, help="also write the figures as JSON")


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


def run(args) -> int:
    data, n = make_stream(args.seconds)
    results = {}
    for chunk in (1, 64, 4096, len(data)):
        results[chunk] = _frames_per_s(FrameDecoder, data, n, chunk, args.repeat, n)
    ceiling = _frames_per_s(NothingDecoder, data, n, 1, args.repeat, 0)
    print(f"decoder throughput, {n} frames ({len(data)} bytes, {args.seconds:g} s of the densest stream), "
          f"CPU time of this process, median of {args.repeat}")
    print(f"{'feed size (bytes)':>18} {'frames/s':>12} {'× device max (' + str(DEVICE_MAX_FRAMES_PER_S) + '/s)':>24}")
    for chunk, fps in results.items():
        label = "whole stream" if chunk == len(data) else str(chunk)
        print(f"{label:>18} {fps:12.0f} {fps / DEVICE_MAX_FRAMES_PER_S:24.0f}")
    print(f"a Python method that does nothing, fed the same bytes one at a time: {ceiling:.0f} frames/s "
          f"({len(data) / n:.1f} calls a frame; the byte-fed decoder reaches {results[1] / ceiling:.2f} of it)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"frames": n, "frames_per_s": {str(k): v for k, v in results.items()},
                       "empty_method_byte_fed_frames_per_s": ceiling,
                       "device_max_frames_per_s": DEVICE_MAX_FRAMES_PER_S}, f, indent=2)
    return 0
