"""The held-sphere generator's new motions (start-up turn, long hold with aims, hard stops, warm-up bias) are
what they say, and the drift bench's figures measure what they name on hand-made pointer paths."""

import numpy as np
import pytest

from sphere.bench import drift as D
from sphere.sim import hold as H


@pytest.mark.slow
def test_warm_up_bias_starts_at_its_value_and_ramps_linearly_then_stays():
    script = H.long_hold_script(400.0, 3)
    h = H.hold_script(400.0, 3, H.WARM_UP, script=script)
    rate = h.motion.rate_hz
    b = h.bias_dps
    assert np.allclose(np.abs(b[0]), 0.6)
    assert np.allclose(np.abs(b[int(150 * rate)]), 0.6 + 0.25, atol=0.01)  # half way up the 5-minute ramp
    assert np.allclose(np.abs(b[int(300 * rate)]), 1.1, atol=0.01) and np.allclose(b[int(300 * rate)], b[-1], atol=0.01)
    assert np.all(np.sign(b[0]) == np.sign(b[-1]))
    # the sensor's gyro = truth + that bias + noise, minute by minute
    err = np.degrees(h.motion.gyr_rad_s) - h.true_gyro_dps
    k = int(60 * rate)
    assert np.allclose(err[4 * k: 5 * k].mean(axis=0), b[4 * k: 5 * k].mean(axis=0), atol=0.01)


def test_long_hold_is_never_laid_down_and_aims_every_20_s():
    script = H.long_hold_script(600.0, 1)
    assert {s[0] for s in script} == {"held", "turn"} and H.script_seconds(script) == pytest.approx(600.0)
    turns = [s for s in script if s[0] == "turn"]
    assert 24 <= len(turns) <= 35  # every 17–23 s
    assert all(s[2] in ("fine", "slow") and 1.0 <= abs(s[3]) <= 15.0 for s in turns)


def test_startup_turn_begins_at_switch_on():
    h = H.hold_script(14.0, 2, H.CLEAN, script=H.startup_turn_script(20.0, 3.0, 11.0))
    yaw = h.true_gyro_dps[:, 2]
    rate = h.motion.rate_hz
    assert yaw[int(0.1 * rate): int(2.9 * rate)] == pytest.approx(20.0, abs=1e-6)
    assert np.abs(yaw[int(3.1 * rate):]).max() < 1e-6
    assert h.phases[0].kind == "turn" and h.phases[0].start_s == 0.0


def test_stops_script_has_every_band_with_hard_stops():
    script = H.stops_script(4)
    bands = [s[2] for s in script if s[0] == "turn"]
    assert all(bands.count(b) == 3 for b in H.BANDS)
    assert H.HARD_STOPS.ramp_s == 0.01


def _path(t, x, y):
    return np.column_stack([t, x, y, x, y])


def test_startup_figures_measure_travel_and_speed_after_the_put_down():
    sc = D.scenario("startup-mag", 1)
    t = np.arange(0.25, sc.seconds, 0.005)
    truth = 48.0 * 20.0 * (np.minimum(t, 3.0) - 0.25)  # follows the turn exactly ...
    x = truth + np.where(t > 3.0, 2.0 * (t - 3.0), 0.0)  # ... then creeps 2 px/s
    f = D.measure(sc, _path(t, x, 0 * t), 0.25)
    assert f["travel_err"] == pytest.approx(2.0 / 2640, abs=0.003)
    assert f["speed_px_s"] == pytest.approx(2.0, abs=0.05)


def test_long_figures_give_the_creep_per_minute_relative_to_the_hand():
    sc = D.Scenario("long", 0, H.hold_script(130.0, 0, H.CLEAN, script=H.long_hold_script(130.0, 0)), 130.0)
    n = int(130.0 * D.RATE_HZ)
    ideal = D._recording(sc, n).ideal_px
    t = np.arange(n) / D.RATE_HZ
    creep = np.where(t < 60, 3.0, 0.5)  # px/s: 3 in minute 1, 0.5 after
    x = ideal[:, 0] + np.cumsum(creep) / D.RATE_HZ
    f = D.measure(sc, _path(t, x, ideal[:, 1]), 0.0)
    assert f["creep_px_s"][0] == pytest.approx(3.0, abs=0.05)
    assert f["creep_px_s"][1] == pytest.approx(0.5, abs=0.05)


def test_x_samples_are_timed_by_the_exact_state_so_the_next_turn_is_not_read_as_drift():
    """The X pointer's samples get the device time of the daemon's own state they equal: the first pixels of a
    turn back (within 3 px of where the pointer stopped, and of states before the stop) belong to that turn,
    not to the held second after the stop (the rule "first state within 3 px" put them there: 3 px/s of drift
    on a pointer that did not move)."""
    t = 0.5 + np.arange(700) * 0.005  # device time of the daemon's states, 200 Hz
    x = np.concatenate([-np.arange(11), np.full(400, -10), -10 + np.arange(1, 290)]).astype(float)
    ref = np.column_stack([t, x, 0 * x])
    wall = np.arange(0.0, 3.0, 0.001)  # the X pointer read at 1 kHz, the replay at speed 2 from wall 0.2
    k = np.clip(np.searchsorted(t, (wall - 0.2) * 2 + 0.5, side="right") - 1, 0, len(t) - 1)
    a = np.column_stack([wall, x[k], 0 * wall])
    times = D.device_times(a, ref, 2.0)
    first = np.maximum.accumulate(np.where(np.r_[True, np.diff(x) != 0], np.arange(len(x)), 0))
    assert np.array_equal(times, t[first[k]])  # each sample at the time its state began
    stop = 0.5 + 10 * 0.005
    grid = D.on_grid(np.column_stack([times, a[:, 1:]]), 3.0)
    held = grid[int((stop + 0.45) * D.RATE_HZ): int((stop + 1.45) * D.RATE_HZ), 0]
    assert np.all(held == -10)


def test_anchored_times_keep_an_x_only_move_at_its_time_and_a_late_replay_out_of_the_held_second():
    """anchored_times: every step of the X pointer onto the daemon's state takes that state's time (a replay
    that fell behind 0.2 s at the first stop does not shift the later ones), and a pixel the X pointer moves
    while the daemon's pointer stands still is placed at its own time, inside the held second, where
    device_times folds it back onto the state before it (and the drift would not be seen)."""
    t = 0.5 + np.arange(1000) * 0.005  # device time of the daemon's states, 200 Hz
    # a 10-px move, held 2 s, a 10-px move back, held
    x = np.concatenate([-np.arange(11), np.full(400, -10), -10 + np.arange(1, 11), np.full(579, 0)]).astype(float)
    ref = np.column_stack([t, x, 0 * x])
    wall = np.arange(0.0, 4.0, 0.001)
    dev = (wall - 0.2) * 2 + 0.5
    dev = np.where(wall > 0.21, np.maximum(0.5 + 0.02, dev - 0.4), dev)  # the replay stalls 0.2 s after its start
    k = np.clip(np.searchsorted(t, dev, side="right") - 1, 0, len(t) - 1)
    a = np.column_stack([wall, x[k], 0 * wall])
    stop = 0.5 + 10 * 0.005
    own = (dev > stop + 0.9) & (dev < 0.5 + 410 * 0.005)  # the X pointer alone 1 px down in the held second
    a[own, 2] = 1.0
    times = D.anchored_times(a, ref, 2.0)
    assert np.all(np.diff(times) >= -1e-9)
    steps = np.r_[True, np.diff(x[k]) != 0] & ~own
    assert np.array_equal(times[steps], t[k][steps])  # every step at the time its state began
    grid = D.on_grid(np.column_stack([times, a[:, 1:]]), 5.0)
    held = grid[int((stop + 0.45) * D.RATE_HZ): int((stop + 1.45) * D.RATE_HZ)]
    assert np.all(held[:, 0] == -10)
    assert held[0, 1] == 0 and held[-1, 1] == 1  # the X-only pixel shows inside the held second
    folded = D.on_grid(np.column_stack([D.device_times(a, ref, 2.0), a[:, 1:]]), 5.0)
    assert np.ptp(folded[int((stop + 0.45) * D.RATE_HZ): int((stop + 1.45) * D.RATE_HZ), 1]) == 0  # not seen there
