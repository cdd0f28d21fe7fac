"""`sphere bench pointer`: its figures on constructed motion (so they mean what they say), and the command
on the shipped trials and synthetic:hold seeds through the daemon's path."""

import json
import subprocess
import sys

import numpy as np
import pytest

from sphere.bench import pointer as bench
from sphere.sim.hold import Phase

R = bench.RATE_HZ


def _turn_recording(delay_s=0.0, overshoot_px=0.0, drift_px_s=0.0, scale=1.0):
    """A clean 1-s yaw turn at 10 °/s (480 px to the left) from 1 s, and a pointer path made from it."""
    n = int(4.0 * R)
    t = np.arange(n) / R
    ideal = np.zeros((n, 2))
    ideal[:, 0] = -np.clip(t - 1.0, 0.0, 1.0) * 480.0
    rec = bench.Recording("t", "clean", [None] * n, phases=[Phase("held", 0.0, 1.0), Phase("turn", 1.0, 2.0, "slow", 10.0, "yaw"),
                                                         Phase("held", 2.0, 4.0)])
    rec.ideal_px = rec.intent_px = ideal
    rec.wander_px = np.zeros_like(ideal)
    path = np.zeros_like(ideal)
    path[:, 0] = -np.clip(t - 1.0 - delay_s, 0.0, 1.0) * 480.0 * scale
    after = t >= 2.0 + delay_s
    path[after, 0] -= overshoot_px * np.sin(np.pi * np.clip((t[after] - 2.0 - delay_s) / 0.2, 0, 1))
    path[:, 1] = np.where(t > 2.0, (t - 2.0) * drift_px_s, 0.0)
    return rec, path


def test_lag_is_the_time_to_half_travel():
    rec, path = _turn_recording(delay_s=0.030)
    (f,) = bench.turn_figures(path, rec)
    assert f["lag_ms"] == pytest.approx(30.0, abs=0.5)
    rec, path = _turn_recording()
    assert bench.turn_figures(path, rec)[0]["lag_ms"] == pytest.approx(0.0, abs=0.5)


def test_overshoot_drift_and_travel_are_seen():
    rec, path = _turn_recording(overshoot_px=5.0)
    assert bench.turn_figures(path, rec)[0]["overshoot_px"] == pytest.approx(5.0, abs=0.05)
    rec, path = _turn_recording(drift_px_s=3.0)
    assert bench.turn_figures(path, rec)[0]["drift_px_s"] == pytest.approx(3.0, abs=0.01)
    rec, path = _turn_recording(scale=1.04)
    assert bench.turn_figures(path, rec)[0]["travel_err"] == pytest.approx(0.04, abs=0.002)


def test_travel_against_the_aim_leaves_the_hands_sway_out():
    """The hand sways 6 px back to the right in the window after the stop (not meant): the pointer that ends where
    the aim ends reads +1.3 % against where the hand points (480 px of 474) and 0 against the aim."""
    rec, path = _turn_recording()
    t = np.arange(len(path)) / R
    rec.ideal_px = rec.ideal_px.copy()
    rec.ideal_px[t >= 2.3, 0] += 6.0
    (f,) = bench.turn_figures(path, rec)
    assert f["aim_err"] == pytest.approx(0.0, abs=1e-9)
    assert f["travel_err"] == pytest.approx(480.0 / 474.0 - 1.0, abs=1e-9)


def test_another_revisions_daemon_is_measured_on_the_same_path():
    """--against's side (the daemon of a given host/ tree fed the recording's wire frames) run with this tree
    gives exactly the pointer the bench's own path gives for the daemon's default."""
    import os

    rec = bench.hold_recordings([2], seconds=12.0, frames=True)[0]
    host = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(bench.__file__))))
    ((whole, exact),) = bench.revision_paths(host, [rec])
    own, own_exact = bench.pointer_paths(rec, bench.DEFAULT)
    assert np.array_equal(whole, own) and np.allclose(exact, own_exact, atol=1e-9)
    assert np.ptp(whole, axis=0).max() >= 10  # it moved


def test_window_jitter_is_the_shake_about_a_line():
    rng = np.random.default_rng(0)
    line = np.stack([np.arange(1000) * 0.3, np.zeros(1000)], axis=1)
    sq, n = bench.window_jitter(line + rng.normal(0, 0.2, line.shape), [(0, 1000)])
    assert n == 1000 and 0.25 < np.sqrt(sq / n) < 0.3  # 2-D noise of 0.2 per axis, less the fit
    assert bench.window_jitter(line, [(0, 1000)])[0] == pytest.approx(0.0, abs=1e-12)


def test_hold_trace_is_what_its_parameters_say():
    """The generator, measured against its own definition: tremor size and band, bias, turn rates."""
    from sphere.sim.hold import hold_script

    h = hold_script(42.0, seed=5)
    rate = h.motion.rate_hz
    held = [p for p in h.phases if p.kind == "held"]
    a, b = int(held[1].start_s * rate) + 200, int(held[1].end_s * rate) - 200
    # tremor: the rotation about each axis in 8-12 Hz is ~0.1° RMS (integrated body rate, detrended)
    g = h.true_gyro_dps[a:b]
    angle = np.cumsum(g, axis=0) / rate
    spec = np.fft.rfft(angle - angle.mean(axis=0), axis=0)
    f = np.fft.rfftfreq(len(angle), 1 / rate)
    band = (f >= 8) & (f <= 12)
    rms = np.sqrt(2 * np.sum(np.abs(spec[band]) ** 2, axis=0)) / len(angle)
    assert np.all((rms > 0.05) & (rms < 0.15)), rms
    # the sensor's gyro = truth + bias + noise
    err = np.degrees(h.motion.gyr_rad_s) - h.true_gyro_dps
    assert np.allclose(err[:2000].mean(axis=0), h.bias_dps[:2000].mean(axis=0), atol=0.05)
    assert err.std(axis=0) == pytest.approx([0.38] * 3, rel=0.1)
    for p in h.phases:
        if p.kind == "turn":
            lo, hi = {"fine": (1, 5), "slow": (5, 30), "medium": (30, 90), "fast": (90, 200)}[p.band]
            assert lo <= abs(p.rate_dps) <= hi


def test_the_hand_hold_loses_nothing_of_a_turn_through_the_daemons_path():
    """A held-sphere seed through the daemon's path (the bench's recording): over every turn, from 0.05 s before
    its start to 0.1 s after its stop, the pointer with the hand hold moves as far as without it (within 2 px: a
    move's start is carried on release, not lost), and the held pointer stands still before the turn. The
    bench's 3 °/s travel figure differs between the two only by the hand's sway around the turn, which a held
    pointer does not follow."""
    rec = bench.hold_recordings([1])[0]
    held, _ = bench.pointer_paths(rec, "tremor")
    free, _ = bench.pointer_paths(rec, "tremor", pointer={"hold_band_dps": 0.0})
    turns = [p for p in rec.phases if p.kind == "turn" and p.end_s + 0.2 < len(held) / R]
    assert len(turns) >= 10
    for ph in turns:
        a, b = int(round((ph.start_s - 0.05) * R)), int(round((ph.end_s + 0.1) * R))
        u = bench._direction(ph)
        moved_held, moved_free = (held[b] - held[a]) @ u, (free[b] - free[a]) @ u
        assert abs(moved_held - moved_free) <= 2.0, (ph, moved_held, moved_free)
        assert moved_held >= 0.9 * abs(ph.rate_dps) * (ph.end_s - ph.start_s) * 48.0  # the turn, at 48 px/°
    fine = [p for p in turns if p.band == "fine"]
    assert fine and all(np.ptp(held[int(round((p.start_s - 0.3) * R)): int(round((p.start_s - 0.05) * R))] @ bench._direction(p)) == 0
                        for p in fine)


def _bench_pointer(tmp_path, *args):
    """`sphere bench pointer` on 20 s of BROAD and one seed, untuned, with ``args``: its output and its JSON."""
    from sphere.broad import BroadMissing

    try:
        bench.with_breaks_trials()
    except BroadMissing as e:
        pytest.skip(str(e))
    out = tmp_path / "pointer.json"
    r = subprocess.run([sys.executable, "-m", "sphere.cli", "bench", "pointer", "--seconds", "20", "--seeds", "1",
                        "--no-tune", *args, "--json", str(out)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return r, json.loads(out.read_text())


@pytest.mark.slow
def test_bench_pointer_command(tmp_path):
    r, data = _bench_pointer(tmp_path, "--filters", "none,tremor,tiered")
    assert set(data["filters"]) == {"none", "tremor", "tiered"}
    none = data["filters"]["none"]["defaults"]["figures"]
    tremor = data["filters"]["tremor"]["defaults"]["figures"]
    assert 5.0 < none["held_jitter_px"] < 9.0  # 0.1° RMS per axis at 48 px/° through nothing
    assert tremor["held_jitter_px"] < 1.5 < none["held_jitter_px"]
    assert abs(none["lag_fast_ms"]) < 10.0 and tremor["lag_fine_ms"] - tremor["lag_fast_ms"] <= 40.0
    assert "held px" in r.stdout and "* the daemon's default (pointer.smoothing = tremor)" in r.stdout
    # the default mapper on the motions' true rates: every figure, and no sensor noise left to shake it lying still
    truth = data["true_rates"]["figures"]
    assert set(truth) == set(tremor) and truth["rest_jitter_px"] < 0.05
    assert " tremor (true rates)" in r.stdout


@pytest.mark.slow
def test_bench_pointer_against_a_revision(tmp_path):
    """`--against REV`: the daemon of REV (here this very commit) on the same TEST motions, a row beside the default
    and the ratios; the two match when the code does."""
    r, data = _bench_pointer(tmp_path, "--filters", "tremor", "--against", "HEAD")
    mine, theirs = data["filters"]["tremor"]["defaults"]["figures"], data["against"]["figures"]
    # the daemon and its filters unchanged since HEAD
    same = ["git", "diff", "--quiet", "HEAD", "--", "host/sphere", ":(exclude)host/sphere/bench"]
    if subprocess.run(same, cwd=bench.__file__.rsplit("/host/", 1)[0]).returncode == 0:
        for k in ("fine_travel_err_max", "fine_aim_err_max", "lag_fine_ms", "held_jitter_px"):
            assert theirs[k] == pytest.approx(mine[k], abs=1e-9), k
    assert " HEAD (its defaults)" in r.stdout and "this tree / HEAD: " in r.stdout and "3°/s aim" in r.stdout


@pytest.mark.slow
def test_fine_lag_on_the_pixels_shown_is_no_worse_than_before_the_hand_hold(tmp_path):
    """Issue 28: the held-sphere bench's fine − fast lag (TEST seeds, the whole pixels the pointer shows) no worse than
    feb1c4d's +28.8 ms (before the hand hold). A pixel stepped at 0.8 px of motion (`step_at_px`, the default) instead
    of at whole pixels only (1, as before: 29.5 ms) makes a slow move's pixels come 0.2 px earlier; what is measured
    with the sub-pixel remainder (overshoot, drift) is the same either way."""
    from sphere.broad import BroadMissing

    try:
        bench.with_breaks_trials()
    except BroadMissing as e:
        pytest.skip(str(e))
    figures = {}
    for extra in ((), ("--set", "pointer.step_at_px=1")):
        out = tmp_path / "pointer.json"
        r = subprocess.run([sys.executable, "-m", "sphere.cli", "bench", "pointer", "--filters", "tremor", "--no-tune",
                            *extra, "--json", str(out)], capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, r.stderr
        figures[extra] = json.loads(out.read_text())["filters"]["tremor"]["defaults"]["figures"]
    now, before = figures[()], figures[extra]
    print(f"fine − fast lag {now['fine_minus_fast_ms']:.1f} ms, with whole pixels only {before['fine_minus_fast_ms']:.1f}")
    assert now["fine_minus_fast_ms"] <= 28.8
    assert before["fine_minus_fast_ms"] - now["fine_minus_fast_ms"] >= 1.0
    assert now["held_jitter_px"] <= 0.95
    for k in ("overshoot_px", "drift_px_s"):
        assert now[k] == before[k], k


def test_bench_pointer_bad_filter_name_is_one_line():
    r = subprocess.run([sys.executable, "-m", "sphere.cli", "bench", "pointer", "--filters", "tremor,kalmann"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "unknown filter kalmann" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.slow
def test_bench_pointer_pose_mode(tmp_path):
    """The 3-D stream's pose filter (the daemon's PoseFilter) on synthetic:hold: the issue's targets."""
    out = tmp_path / "pose.json"
    r = subprocess.run([sys.executable, "-m", "sphere.cli", "bench", "pointer", "--pose", "--seeds", "1",
                        "--filters", "none,tremor", "--json", str(out)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    data = json.loads(out.read_text())["filters"]
    assert data["tremor"]["still_jitter_deg"] <= 0.05 and data["tremor"]["held_jitter_deg"] <= 0.1
    assert data["tremor"]["held_jitter_deg"] < 0.5 * data["none"]["held_jitter_deg"]
    assert data["tremor"]["lag_slow_ms"] <= 20.0


def test_pose_filter_has_no_jump_at_180_degrees():
    from sphere.quaternion import conj, mul
    from sphere.smoothing.pose import PoseFilter, exp_deg, log_deg

    f = PoseFilter("tremor")
    prev, worst = None, 0.0
    for i in range(1600):  # 170° → 530° about z at 90 °/s, through ±180° twice
        angle = (170.0 + i * 0.005 * 90.0 + 180.0) % 360.0 - 180.0
        q, _ = f.update(exp_deg((0.0, 0.0, angle)), 0.005)
        if prev is not None:
            worst = max(worst, float(np.linalg.norm(log_deg(mul(q, conj(prev))))))
        prev = q
    assert worst < 0.6  # 0.45° per sample, nothing like a 360° flip
    assert PoseFilter("none").update(exp_deg((10.0, 20.0, 30.0)), 0.005)[0] == pytest.approx(exp_deg((10.0, 20.0, 30.0)))
