"""Events → actions, the freeze around taps, modes, and the daemon's per-packet work on synthetic input."""

from __future__ import annotations

from sphere.link.capture import DecodedPacket
from sphere.daemon.actions import MotionHistory
from sphere.daemon.app import SphereMouse
from sphere.daemon.backends.memory import RecordingBackend
from sphere.daemon.config import Config
from sphere.daemon.scripted_sphere import script_frames
from sphere.protocol import FrameDecoder, TimeUnwrapper


def cfg(**sections):
    c = Config()
    over = {"outputs.page": {"enabled": False}}
    over.update(sections)
    return c.with_overrides(over, "test")


def packets(script):
    dec = FrameDecoder()
    unwrap = TimeUnwrapper()
    out = []
    for _, f in script_frames(script):
        for p in dec.feed(f):
            t = getattr(p, "t_us", None)
            out.append(DecodedPacket(p, unwrap(t) if t is not None else None))
    return out


def feed(daemon, script):
    for dp in packets(script):
        daemon.handle(dp)


class Src:
    state = "test"
    generation = 1


def make(**sections):
    backend = RecordingBackend()
    d = SphereMouse(cfg(**sections), Src(), backend, log=lambda m: None)
    return d, backend


def test_history_undo():
    h = MotionHistory()
    for t in range(0, 100_000, 5_000):
        h.add(t, 2, -1)
    assert h.undo_since(80_000) == (-8, 4)
    assert h.undo_since(80_000) == (0, 0)


def test_single_tap_clicks_at_the_aimed_point():
    d, b = make()
    feed(d, [("still", 0.5), ("turn", (0, 0, 1), 10.0, 0.5), ("still", 0.2), ("tap", "single_tap"), ("still", 0.3)])
    # 5° left at 1920/40 = 240 px; the knock's first (unflagged) sample pushed it, the undo took it back
    assert [c[0] for c in b.clicks] == ["left"]
    assert b.x_at_click[0] == -240
    assert b.x == -240


def test_without_undo_the_knock_moves_the_click():
    d, b = make(freeze={"tap_before_ms": 0})
    feed(d, [("still", 0.5), ("turn", (0, 0, 1), 10.0, 0.5), ("still", 0.2), ("tap", "single_tap"), ("still", 0.3)])
    assert b.x_at_click[0] != -240


def test_pointer_frozen_after_tap():
    d, b = make(freeze={"tap_after_ms": 300})
    feed(d, [("still", 0.5), ("tap", "single_tap"), ("turn", (0, 0, 1), 10.0, 0.25)])
    assert b.x == 0  # the whole turn happened inside the freeze


def test_double_tap_after_single_makes_two_clicks():
    d, b = make()
    feed(d, [("still", 0.3), ("tap", "single_tap"), ("still", 0.1), ("tap", "double_tap"), ("still", 0.2)])
    assert [c[0] for c in b.clicks] == ["left", "left"]


def test_double_tap_as_right_click_waits_for_the_single():
    d, b = make(events={"double_tap": "right_click", "single_tap_wait_ms": 250})
    feed(d, [("still", 0.3), ("tap", "single_tap"), ("still", 0.1), ("tap", "double_tap"), ("still", 0.5)])
    assert [c[0] for c in b.clicks] == ["right"]
    d2, b2 = make(events={"double_tap": "right_click", "single_tap_wait_ms": 250})
    feed(d2, [("still", 0.3), ("tap", "single_tap"), ("still", 0.5)])
    assert [c[0] for c in b2.clicks] == ["left"]


def test_free_fall_cycles_modes():
    d, b = make()
    assert d.mode == "pointer"
    feed(d, [("still", 0.3), ("free_fall", 0.3), ("still", 1.0)])
    assert d.mode == "tilt"
    feed(d, [("free_fall", 0.3), ("still", 1.0)])
    assert d.mode == "3d"
    feed(d, [("free_fall", 0.3), ("still", 1.0)])
    assert d.mode == "pointer"
    assert d.mode_changes == ["tilt", "3d", "pointer"]


def test_toss_does_not_move_the_pointer():
    d, b = make()
    feed(d, [("still", 0.3), ("turn", (0, 1, 0), 40.0, 0.1), ("free_fall", 0.3), ("still", 1.0)])
    assert b.x == 0 and b.y == 0  # the pitch just before the toss was undone too (free_fall_before_ms)


def test_3d_mode_never_moves_or_clicks():
    d, b = make(mode={"start": "3d", "cycle": ["pointer", "tilt", "3d"]})
    feed(d, [("still", 0.3), ("turn", (0, 0, 1), 30.0, 0.5), ("tap", "single_tap"), ("still", 0.3)])
    assert b.x == 0 and b.clicks == []


def test_tilt_mode_velocity_and_recentre():
    d, b = make(mode={"start": "tilt"})
    feed(d, [("still", 0.3), ("tilt", (0, 0, 1), 20.0, 0.2), ("still", 1.0)])
    assert b.x < -300  # held 20° left: the pointer keeps going left
    x = b.x
    d.recentre()
    feed(d, [("still", 1.0)])
    assert b.x == x  # the held pose is the new centre


def test_pause_action_clutch():
    d, b = make(events={"single_tap": "pause"}, freeze={"tap_after_ms": 0})
    feed(d, [("still", 0.3), ("tap", "single_tap"), ("turn", (0, 0, 1), 10.0, 0.5), ("tap", "single_tap"),
             ("turn", (0, 0, 1), 10.0, 0.5), ("still", 0.2)])  # the smoothing delivers the end of a move later
    assert not d.paused
    assert abs(b.x + 240) <= 2  # only the second turn moved the pointer


def test_device_orientation_used_when_host_filter_off():
    d, b = make(orientation={"source": "device"}, mode={"start": "tilt"})
    assert not d.motion.uses_host_filter
    feed(d, [("still", 0.3), ("tilt", (0, 0, 1), -20.0, 0.2), ("still", 1.0)])
    assert b.x > 300


def test_gyro_bias_is_learnt_while_still():
    from sphere.daemon.motion import GyroBias

    bias = GyroBias(still_dps=3.0, still_time_s=0.5)
    for _ in range(200):
        bias.add((1.5, -0.7, 0.2), 1.0, 0.005, (20.0, 0.0, -44.0))
    assert [round(v, 6) for v in bias.bias] == [1.5, -0.7, 0.2]
    # a slow steady turn is not taken for bias: the compass moves
    for i in range(200):
        bias.add((1.5, -0.7, 5.2), 1.0, 0.005, (20.0, i * 0.05, -44.0))
    assert round(bias.bias[2], 6) == 0.2



def test_orientation_only_stream_still_points():
    """A link too slow for raw samples (orientation only): pointer mode uses the rate between orientations."""
    d, b = make()
    only = [dp for dp in packets([("still", 0.5), ("turn", (0, 0, 1), 10.0, 1.0), ("still", 0.2)])
            if dp.packet.NAME != "RAW_SAMPLE"]
    for dp in only:
        d.handle(dp)
    assert abs(b.x + 480) <= 3 and abs(b.y) <= 1  # 10° left at 1920 px / 40°


def test_recorded_captures_replay_cleanly():
    """Every capture the simulator recorded into tests/captures replays through the daemon without error."""
    import pytest
    from sphere.daemon.sources.replay import ReplaySource
    from sphere.paths import repo_path

    caps = sorted(repo_path("tests", "captures").glob("*.bin"))  # the README there names them sim_*.bin
    if not caps:
        pytest.skip("no recorded captures in tests/captures yet")
    for cap in caps:
        src = ReplaySource(cap, speed=0)
        d = SphereMouse(cfg(), src, RecordingBackend(), log=lambda m: None)
        d.run()
        assert src.stats.frames_ok > 0, cap
