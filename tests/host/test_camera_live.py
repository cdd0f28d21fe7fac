"""The camera as a live source: a video from the virtual webcam read in a thread, the ball tracked, the
fixes folded into the hybrid tracker beside the trial's IMU samples, as a daemon would."""

from __future__ import annotations

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2", reason="opencv-python-headless (the camera extra) is part of the setup")

from sphere import broad  # noqa: E402
from sphere.cli import main  # noqa: E402


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    try:
        broad.trial_paths()
    except broad.BroadMissing as e:
        pytest.skip(f"BROAD trials are needed: {e}")
    out = tmp_path_factory.mktemp("live") / "v.avi"
    assert main(["camera", "render", "--trial", "10", "--start", "40", "--seconds", "3", "-o", str(out)]) == 0
    truth = np.loadtxt(str(out) + ".csv", delimiter=",", skiprows=1)
    return out, truth


@pytest.mark.slow
def test_track_a_video_file(video, capsys):
    path, truth = video
    assert main(["camera", "track", str(path)]) == 0
    cap = capsys.readouterr()
    rows = np.loadtxt(cap.out.splitlines()[1:], delimiter=",")
    assert len(rows) >= 0.9 * len(truth)
    assert "frames, ball in" in cap.err
    # each frame's position against the truth at its exposure (MJPG compression and all): a few mm
    idx = rows[:, 0].astype(int)
    err = np.linalg.norm(rows[:, 2:5] - truth[idx, 4:7], axis=1)
    assert np.median(err) < 0.005


def test_live_tracker_with_the_trials_imu(video):
    from sphere.camera import trials
    from sphere.camera.live import CameraSource, LiveTracker

    path, truth = video
    rt = trials.rendered_trial("10", 40, 3)  # the same stretch: its IMU samples and its truth
    src = CameraSource(str(path), arrival_times=truth[:, 3]).start()
    live = LiveTracker(src)
    src._thread.join(timeout=60)  # a file: the thread reads ahead; each fix is used once it has "arrived"
    out = np.full((len(rt.t), 3), np.nan)
    for i, t in enumerate(rt.t):
        p = live.sensor(t, rt.q_host_enu[i], rt.trial.acc_m_s2[i])  # taken at t, arrives 4 ms later
        if p is not None:
            out[i] = p
    assert src.error is None and src.found >= 0.9 * src.frames
    ok = np.all(np.isfinite(out), axis=1) & (rt.t > 1.5)
    assert ok.sum() > 300
    err = np.linalg.norm(out[ok] - rt.truth_cam(rt.t[ok] + 0.004), axis=1)
    assert np.sqrt(np.mean(err ** 2)) < 0.02


def test_a_camera_that_is_not_there(capsys):
    assert main(["camera", "track", "/nonexistent/video.avi"]) == 2
    assert "cannot open video file" in capsys.readouterr().err


def test_a_camera_index_that_is_not_there_says_one_line():
    """`sphere-mouse --camera 7` with no /dev/video7: our line alone (OpenCV's own warnings silenced), exit 2."""
    import subprocess
    import sys

    code = "import sys; from sphere.daemon.cli import main; sys.exit(main(sys.argv[1:]))"
    out = subprocess.run([sys.executable, "-c", code, "--camera", "7", "--backend", "log", "--quiet"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "cannot open camera 7" in lines[0] and "ls /dev/video*" in lines[0], out.stderr


def test_frame_clock_takes_out_the_arrival_jitter():
    """The virtual camera's frames arrive 35 ms + an exponential tail (mean 5 ms) after the middle of their
    exposure; the clock stamps them from the camera's own regular period, frames the camera dropped included,
    and starts again when the camera pauses."""
    from sphere.camera.live import FrameClock

    rng = np.random.default_rng(3)
    period = 1 / 30.0
    k = np.arange(400)
    k = k[(k % 37) != 5]  # the camera drops a frame now and then
    mid = 10.0 + k * period * (1 + 1e-4) + rng.normal(0, 0.0005, len(k))
    mid[len(k) // 2:] += 2.0  # a pause of 2 s: the frames go on from there
    arrival = mid + 0.035 + rng.exponential(0.005, len(k))
    clock = FrameClock(0.040, period)
    est = np.array([clock(a) for a in arrival])
    plain = arrival - 0.040 - mid
    err = est - mid
    steady = np.r_[60:len(k) // 2, len(k) // 2 + 60:len(k)]  # 2 s after each start of the fit
    assert np.std(plain) > 0.004 and np.abs(plain).max() > 0.02
    assert np.abs(err[steady].mean()) < 0.001 and np.std(err[steady]) < 0.0015 and np.abs(err[steady]).max() < 0.005
    assert np.abs(err).max() < 0.02
