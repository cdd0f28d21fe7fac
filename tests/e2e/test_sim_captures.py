"""The committed captures made by the virtual board (tests/captures/sim_*.bin, see tests/captures/README):
each decodes cleanly and holds what its scenario promises. They need neither simavr nor the firmware."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sphere.sim.analysis import summarise

CAPTURES = Path(__file__).resolve().parents[1] / "captures"
SIM_CAPTURES = sorted(CAPTURES.glob("sim_*.bin"))


def _need(name: str):
    p = CAPTURES / name
    if not p.exists():
        pytest.skip(f"{p} not made yet (hardware/sim/make_captures.sh)")
    return summarise(p)


@pytest.mark.parametrize("path", SIM_CAPTURES, ids=[p.name for p in SIM_CAPTURES])
def test_capture_decodes_cleanly(path):
    s = summarise(path)
    d = s.decoder
    assert s.hello is not None and s.hello.sensors_found == 0b111
    assert d["crc_errors"] == 0 and d["framing_errors"] == 0 and d["seq_gaps"] == 0
    assert path.stat().st_size < 200_000, "captures stay small: seconds, not minutes"
    stats = path.with_suffix(".stats.json")
    if stats.exists():
        assert json.loads(stats.read_text())["frames_sent"] == d["frames_ok"]


def test_tapping_capture_has_taps():
    s = _need("sim_24_tapping.bin")
    assert any(e.event_name in ("single_tap", "double_tap") for e in s.events)


def test_toss_capture_has_a_free_fall():
    s = _need("sim_toss.bin")
    assert any(e.event_name == "free_fall" for e in s.events)


def test_mag_fault_capture_shows_the_fault_and_recovery():
    s = _need("sim_mag_fault.bin")
    oks = [x.sensors_ok for x in s.status]
    assert 0b011 in oks and oks[-1] == 0b111
