"""Issue 16 end to end: a BROAD trial rendered by the virtual webcam, the ball found in every frame, the
hybrid tracker fed with the frames and the trial's IMU as on a live system (`sphere hybrid-eval`)."""

from __future__ import annotations

import json

import pytest

cv2 = pytest.importorskip("cv2", reason="opencv-python-headless (the camera extra) is part of the setup")

from sphere import broad  # noqa: E402
from sphere.cli import main  # noqa: E402


@pytest.fixture(scope="module")
def broad_dir():
    try:
        broad.trial_paths()
    except broad.BroadMissing as e:
        pytest.skip(f"BROAD trials are needed: {e}")


@pytest.fixture(scope="module")
def slow_translation(broad_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("hybrid") / "h.json"
    plots = out.parent / "plots"
    assert main(["hybrid-eval", "--trials", "10:40", "--seconds", "9", "--json", str(out), "--plot", str(plots)]) == 0
    doc = json.loads(out.read_text())
    assert (plots / "hybrid-summary.png").stat().st_size > 1000
    return doc["trials"]["10_undisturbed_slow_translation_A"]


def test_hybrid_meets_the_accuracy_targets_and_beats_the_camera_alone(slow_translation):
    t = slow_translation
    assert 0.5 <= t["distance_range_m"][0] and t["distance_range_m"][1] <= 1.5
    assert t["frames_with_ball"] >= 0.85 * t["frames"] - 30  # all but the 1 s the hand hides it (30 frames)
    h, cam = t["methods"]["hybrid"], t["methods"]["camera"]
    assert h["rmse_lateral_m"] <= 0.01 and h["rmse_depth_m"] <= 0.03
    assert cam["rmse_lateral_m"] > 2 * h["rmse_lateral_m"]
    # the colour blob's centroid and apparent size (the PS Move trackers' method) against our outline fit
    blob = t["methods"]["blob"]
    assert blob["rmse_depth_m"] > 2 * cam["rmse_depth_m"]
    assert t["alignment_error_deg"] < 3.0  # estimated, not given
    assert cam["fixes_over_50mm_after_gate"] == 0 and cam["fixes_used"] >= 0.9 * cam["fixes"]


def test_output_rate_and_latency(slow_translation):
    h, cam = slow_translation["methods"]["hybrid"], slow_translation["methods"]["camera"]
    assert h["output_rate_hz"] >= 100
    assert h["latency_ms"] <= 10
    assert cam["latency_ms"] >= 35  # the camera alone lags by its capture latency


def test_a_one_second_loss_of_the_ball(slow_translation):
    loss = slow_translation["methods"]["hybrid"]["losses"][0]
    assert loss["t1"] - loss["t0"] == pytest.approx(1.0)
    assert loss["error_at_return_m"] <= 0.10
    assert loss["recovery_s"] is not None and loss["recovery_s"] <= 0.5
    imu = slow_translation["methods"]["imu"]
    assert imu["rmse_lateral_m"] > 10 * slow_translation["methods"]["hybrid"]["rmse_lateral_m"]  # IMU alone drifts


@pytest.mark.parametrize("side", [200.0, 20.0, 110.0, 0.0, 270.0])
def test_first_lock_on_a_ball_behind_a_hand_from_the_start(broad_dir, side):
    """Issue 30: a hand over the ball from the first frame (the palm's edge near the ball's centre: about half
    of the outline hidden, two-thirds of the ball or less seen): the first fix within 0.5 s, and no fix of it
    more than 50 mm off."""
    from sphere.camera import evaluation, render, trials

    rt = trials.rendered_trial("10", 40.0, 1.5, occlusions=[render.Occlusion(0.0, 2.0, 0.45, side)], jpeg_quality=85)
    r = evaluation.run(rt)
    assert r.fixes, "no lock at all"
    assert r.fixes[0][0] <= 0.5
    assert max(e for _, e, _ in r.fixes) < 0.05


def test_jitter_at_rest(broad_dir):
    from sphere.camera import evaluation, trials

    rt = trials.rendered_trial("14", 73.0, 4.0, jpeg_quality=85)  # a still phase of trial 14, MJPG-coded
    r = evaluation.run(rt)
    fig = evaluation.figures(r, rt)["hybrid"]
    assert fig["jitter_lateral_m"] <= 0.001 and fig["jitter_depth_m"] <= 0.003


def test_bad_input_is_one_clear_line(capsys, broad_dir):
    assert main(["hybrid-eval", "--seconds", "5"]) == 2
    assert "at least 9" in capsys.readouterr().err
    assert main(["hybrid-eval", "--trials", "99:40"]) == 2
    err = capsys.readouterr().err
    assert "no BROAD trial named '99'" in err and "Traceback" not in err
    assert main(["hybrid-eval", "--trials", "10:900"]) == 2
    assert "choose --start and --seconds inside it" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stopped:  # argparse's line and exit 2
        main(["hybrid-eval", "--trials", "10:soon"])
    assert stopped.value.code == 2 and "argument --trials: '10:soon'" in capsys.readouterr().err


def test_bench_position_cross_validates_the_stream_position_filter(broad_dir, tmp_path, capsys):
    """`sphere bench position` (issue 30): the position filters through the daemon's PoseFilter on the hybrid's
    output, chosen on one stretch and scored on another; one short stretch each here (the full run: docs)."""
    out = tmp_path / "p.json"
    assert main(["bench", "position", "--train", "16:100", "--test", "10:40", "--seconds", "9", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["train"] == ["16:100"] and doc["test"] == ["10:40"]
    none = doc["filters"]["none"]["defaults"]["figures"]
    euro = doc["filters"]["one-euro"]["defaults"]["figures"]
    # the default position smoothing never lags the hybrid's estimate by more than a few ms
    assert euro["latency_ms"] - none["latency_ms"] <= 6.0
    assert euro["rmse_lateral_m"] <= 1.3 * none["rmse_lateral_m"]
    assert doc["choice"]["filter"] in ("none", "one-euro")
    assert "chosen on the train stretches" in capsys.readouterr().out


def test_bench_tracker_breaks_a_loss_down_frame_by_frame(broad_dir, capsys):
    """`sphere bench tracker --breakdown` (issue 30): the AR view's drawn centre through the 1 s loss of the fast trial,
    frame by frame (drawn, the stamp's share, the tracker's), then each cause taken away in turn. On 16:40 the
    accelerometer's offset from the ball's centre is the cause the defaults now model: taking the accelerometer to be
    at the centre leaves fewer of the loss's frames within 3 px."""
    assert main(["bench", "tracker", "--breakdown", "16:40"]) == 0
    out = capsys.readouterr().out
    frames = [line.split() for line in out.splitlines() if line.startswith("  ") and line.split()[0][0].isdigit()]
    assert len(frames) >= 25 and all(len(f) == 4 for f in frames)  # ~30 frames of 1/30 s in the loss

    def share(label):
        line = next(line for line in out.splitlines() if line.startswith(label))
        return float(line[len(label):].split("%")[0])

    assert share("the daemon's path (the defaults)") > share("accelerometer at the centre (lever_sigma_m 0)") + 10, out
