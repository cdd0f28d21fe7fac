"""sphere-mouse on the captures the virtual board recorded (tests/captures, see its README)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sphere import chips
from sphere.link.capture import CaptureFile
from sphere.daemon.app import SphereMouse
from sphere.daemon.backends.memory import RecordingBackend
from sphere.daemon.config import Config
from sphere.daemon.motion import up_from_quat
from sphere.daemon.sources.replay import ReplaySource
from sphere.paths import repo_path

CAPTURES = repo_path("tests", "captures")


def capture(name):
    path = CAPTURES / name
    if not path.exists():
        pytest.skip(f"{path} is not there (hardware/sim/make_captures.sh makes it)")
    return path


def replay(path, **overrides):
    over = {"outputs.page": {"enabled": False}, "output": {"screen_width_px": 1280}}
    over.update(overrides)
    cfg = Config().with_overrides(over, "test")
    backend = RecordingBackend(screen_size=None)
    daemon = SphereMouse(cfg, ReplaySource(path, speed=0), backend, log=lambda m: None)
    daemon.run()
    return daemon, backend


def test_toss_switches_to_tilt_without_moving_the_pointer():
    daemon, backend = replay(capture("sim_toss.bin"))
    assert daemon.mode_changes == ["tilt"]
    assert backend.moves == 0 and backend.clicks == []


def test_tap_clicks_once():
    daemon, backend = replay(capture("sim_24_tapping.bin"))
    assert [c[0] for c in backend.clicks] == ["left"]
    assert daemon.mode_changes == []


def test_still_sphere_with_a_magnetometer_fault_does_not_drift():
    daemon, backend = replay(capture("sim_mag_fault.bin"))
    assert abs(backend.x) <= 2 and abs(backend.y) <= 2
    assert daemon.source.stats.crc_errors == 0


def test_fast_rotation_moves_the_pointer_by_the_turn_about_the_vertical():
    """World axes on real firmware data: the sideways motion is the rotation about the vertical (from the
    device's own orientation), integrated independently here, times the sensitivity."""
    path = capture("sim_07_fast_rotation.bin")
    daemon, backend = replay(path, orientation={"source": "device"}, gyro={"auto_bias": False},
                             pointer={"tightening_dps": 0.0, "smoothing": "none"})
    up = None
    last_t = None
    yaw_deg = 0.0
    for dp in CaptureFile(path).packets():
        p = dp.packet
        if p.NAME == "ORIENTATION":
            up = up_from_quat(p.quat_float)
        elif p.NAME == "RAW_SAMPLE":
            dt = 0.005 if last_t is None or not 0 < dp.t_us - last_t < 100_000 else (dp.t_us - last_t) * 1e-6
            last_t = dp.t_us
            if up is not None:
                g = [v / chips.ITG3200_LSB_PER_DPS for v in p.gyro]
                n = math.sqrt(sum(u * u for u in up))
                yaw_deg += sum(gi * ui for gi, ui in zip(g, up)) / n * dt
    expected_x = -yaw_deg * 1280 / 40.0
    assert abs(expected_x) > 200  # the capture really turns
    assert backend.x == pytest.approx(expected_x, rel=0.02, abs=3)


@pytest.mark.parametrize("mode", ["pointer", "tilt"])
def test_deferred_bias_step_changes_nothing(mode):
    """The daemon issues each move before the host filter's update, its bias step (SphereFilter's defer_bias /
    run_deferred) and GyroBias's trend sums. Every orientation and bias is the same bit for bit as with them inside,
    and so is every move in tilt mode (the tilt waits for the sample's orientation). In pointer mode the mapping's
    vertical until the update is the last one turned by the sample's rate: on this capture's tumbling turns (up to
    the sensor's x axis pointing straight up, where the mapping's forward is least defined) the pointer stays within
    8 px of where the update's vertical takes it, over 37,000 px of travel."""

    def run(defer):
        cfg = Config().with_overrides({"outputs.page": {"enabled": False}, "output": {"screen_width_px": 1280},
                                       "mode": {"start": mode}, "orientation": {"filter": "sphere"}}, "test")
        moves = []

        class Rec(RecordingBackend):
            def move(self, dx, dy):
                moves.append((dx, dy))
                super().move(dx, dy)

        daemon = SphereMouse(cfg, ReplaySource(capture("sim_07_fast_rotation.bin"), speed=0), Rec(screen_size=None),
                             log=lambda m: None)
        m = daemon.motion
        assert m._filter_deferred is not None and m.bias.enabled  # SphereFilter has the split
        m.defer = defer
        quats = []
        handle = daemon.handle
        daemon.handle = lambda dp: (handle(dp), quats.append(m.quat))
        daemon.run()
        return moves, quats, list(m.filter.inner.bias), m.bias.bias, m.bias.updates, m.bias.rejected

    deferred, inline = run(True), run(False)
    assert len(deferred[0]) > 100
    assert repr(deferred[1:]) == repr(inline[1:])
    if mode == "tilt":
        assert deferred[0] == inline[0]
        return
    at_deferred, at_inline = np.cumsum(deferred[0], axis=0), np.cumsum(inline[0], axis=0)
    assert len(at_deferred) == len(at_inline)
    assert np.abs(np.diff(at_inline, axis=0)).sum() > 30_000
    assert np.abs(at_deferred - at_inline).max() <= 8
