"""A sharp move from the hand hold reaches the pointer on its first moving sample: the latency bench's motion
(synthetic:onsets, sharp 120 °/s turns at every phase of the sample clock) through the real firmware on the
virtual board, its capture replayed through the daemon's own packet path (SphereMouse.handle, memory backend):
device time only, no wall clock, so the result is the same on any load."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest

from sphere.bench.drift import _config, daemon
from sphere.protocol import PacketStream, RawSample
from sphere.sim import onsets as O
from sphere.sim import trace as T
from sphere.sim.board import firmware_elf, run_board
from simscenarios import need_board, need_firmware

SECONDS = 9.0  # 15 onsets after the 3-s lead
SEED = 5  # not the latency bench's seed (27)


@pytest.fixture(scope="module")
def capture():
    need_board()
    need_firmware()
    with tempfile.TemporaryDirectory(prefix="sphere-onsets-") as tmp:
        trace = T.to_chips(O.onsets(SECONDS, SEED), gyro_rate_hz=1000.0).write(Path(tmp) / "onsets.bin")
        cap = Path(tmp) / "capture.bin"
        r = run_board(firmware_elf(), trace, SECONDS, cap)
        assert r.returncode == 0, r.stderr[-500:]
        return cap.read_bytes()


def replay(capture: bytes, settings=()):
    """Per RAW_SAMPLE: (gyro z as sent, the pointer's step on it) through SphereMouse.handle."""
    d = daemon(_config(settings))
    out = []
    for dp in PacketStream().feed(capture):
        x = d.backend.x
        d.handle(dp)
        if dp.packet.TYPE == RawSample.TYPE:
            out.append((dp.packet.gyro_dps[2], d.backend.x - x))
    return np.array(out)


def first_moves(rows) -> list[tuple[float, int]]:
    """Per onset (the first sample with a rate after at least 0.1 s without one): its rate and the samples from it
    to the pointer's first step."""
    out, quiet = [], 0
    for i, (gz, _) in enumerate(rows):
        if abs(gz) > 1.0 and quiet >= 20:
            steps = np.flatnonzero(rows[i: i + 10, 1])
            out.append((float(gz), int(steps[0]) if len(steps) else -1))
        quiet = quiet + 1 if abs(gz) <= 1.0 else 0
    return out


def test_a_sharp_onset_moves_the_pointer_on_its_first_moving_sample_as_without_the_hold(capture):
    held = first_moves(replay(capture))
    free = first_moves(replay(capture, ["pointer.hold_band_dps=0"]))
    before = first_moves(replay(capture, ["pointer.hold_pass_dps=0"]))  # the hand hold as it was
    print("first moving sample (°/s) and samples to the first step, held / without the hold / before hold_pass_dps:")
    for h, f, b in zip(held, free, before):
        print(f"  {h[0]:7.1f} {h[1]} / {f[1]} / {b[1]}")
    assert len(held) == len(free) == len(before) >= 12
    assert all(h[1] >= 0 for h in held)
    assert [h[1] for h in held] == [f[1] for f in free]  # the hold delays no onset
    # a first sample of 30 °/s or more (the DLPF's step past its first millisecond) moves the pointer at once; a
    # smaller one (7.8 °/s: the onset came 1 ms before the read) stays under a pixel through the smoothing itself
    assert all(h[1] == 0 for h in held if abs(h[0]) >= 30.0)
    assert any(b[1] > 0 for b in before if abs(b[0]) >= 30.0)  # what hold_pass_dps changed
