"""Time per frame of the camera pipeline on one core: detection + fusion at 640×480 (issue 16's ≤ 5 ms).

Frames are rendered first (not timed): a BROAD stretch as the virtual webcam sees it. Then each frame
goes through the detector (with the track's hint, as live) and the tracker's camera update (which
re-propagates the IMU samples since the exposure); the IMU samples between frames are timed apart.

Times are the thread's CPU time (``time.thread_time``), so other programs sharing the cores do not
inflate them; the wall-clock figures are printed beside them.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from sphere import argtypes, broad
from sphere.camera import trials
from sphere.camera.detect import BallDetector
from sphere.camera.evaluation import NOMINAL_CAMERA_LATENCY_S
from sphere.camera.live import hint_from
from sphere.fusion.hybrid import CameraImuTracker

HELP = "ms per frame of detection + fusion at 640x480 on one core (also `sphere camera bench`)"


def add_arguments(p) -> None:
    p.add_argument("--trial", default="10", help="BROAD trial name or number (default 10)")
    p.add_argument("--start", type=argtypes.non_negative, default=40.0, help="seconds into the trial (default 40)")
    p.add_argument("--seconds", type=argtypes.seconds, default=5.0, help="how long (default 5)")
    p.add_argument("--distance", type=argtypes.distance_m, default=1.0,
                   help="camera to the mean ball position, m (default 1, at most 10)")


def run(args) -> int:
    try:
        import cv2  # noqa: F401  (optional: the camera extra)
    except ImportError:
        print("sphere bench camera: OpenCV is missing; install the camera extra: pip install -e '.[camera]'",
              file=sys.stderr)
        return 1
    try:
        r = measure(args.trial, args.start, args.seconds, args.distance)
    except (broad.BroadMissing, ValueError) as e:
        print(f"sphere bench camera: {e}", file=sys.stderr)
        return 2
    print(f"{r['trial']}: {r['frames']} frames at {r['resolution']}, one OpenCV thread; CPU time of this thread")
    for k, label in (("detect_ms", "detection"), ("fusion_ms", "fusion (camera update)"),
                     ("per_frame_ms", "detection + fusion"), ("per_frame_wall_ms", "  wall clock")):
        v = r[k]
        print(f"  {label:24} mean {v['mean']:6.2f} ms  median {v['p50']:6.2f} ms  p95 {v['p95']:6.2f} ms")
    print(f"  IMU step (prediction)    mean {r['imu_step_us']['mean']:6.1f} µs  p95 {r['imu_step_us']['p95']:6.1f} µs "
          f"at {r['imu_rate_hz']:.0f} Hz")
    verdict = "met" if r["per_frame_ms"]["mean"] <= 5.0 else "MISSED"
    print(f"  target ≤ 5 ms per frame (mean CPU time): {verdict}"
          + (f"; load average {r['load_average_1min']:.1f} while measuring" if r["load_average_1min"] is not None else ""))
    return 0


def measure(trial: str = "10", start_s: float = 40.0, seconds: float = 5.0, distance_m: float = 1.0) -> dict:
    import cv2  # optional dependency: the camera extra (OpenCV)

    cv2.setNumThreads(1)
    rt = trials.rendered_trial(trial, start_s, seconds, distance_m=distance_m, jpeg_quality=85)  # as MJPG sends them
    frames = list(rt.frames())
    det = BallDetector(rt.scene.camera)
    trk = CameraImuTracker()
    detect_ms, fuse_ms, imu_us, wall_ms = [], [], [], []
    clock = time.thread_time
    hint = None
    i = 0
    for f in frames:
        while i < len(rt.t) and rt.t[i] <= f.t_arrival:
            t0 = clock()
            trk.imu(rt.t[i], rt.q_host_enu[i], rt.trial.acc_m_s2[i], gyro_rad_s=rt.trial.gyr_rad_s[i])
            imu_us.append(1e6 * (clock() - t0))
            i += 1
        w0 = time.perf_counter()
        t0 = clock()
        t_exp = f.t_arrival - NOMINAL_CAMERA_LATENCY_S
        hint = hint_from(trk, rt.scene.camera, t_exp, rt.scene.radius_m, hint)
        d = det.detect(f.image, hint)
        t1 = clock()
        if d is not None:
            trk.camera(t_exp, d.center_cam, d.cov)
            hint = (d.center_px, d.radius_px)
        else:
            hint = None
        t2 = clock()
        wall_ms.append(1000 * (time.perf_counter() - w0))
        detect_ms.append(1000 * (t1 - t0))
        fuse_ms.append(1000 * (t2 - t1))
    total = np.array(detect_ms) + np.array(fuse_ms)
    q = lambda x, p: float(np.percentile(x, p))  # noqa: E731
    return {"frames": len(frames), "trial": rt.name, "resolution": f"{rt.scene.camera.width}x{rt.scene.camera.height}",
            "detect_ms": {"mean": float(np.mean(detect_ms)), "p50": q(detect_ms, 50), "p95": q(detect_ms, 95)},
            "fusion_ms": {"mean": float(np.mean(fuse_ms)), "p50": q(fuse_ms, 50), "p95": q(fuse_ms, 95)},
            "per_frame_ms": {"mean": float(total.mean()), "p50": q(total, 50), "p95": q(total, 95)},
            "per_frame_wall_ms": {"mean": float(np.mean(wall_ms)), "p50": q(wall_ms, 50), "p95": q(wall_ms, 95)},
            "load_average_1min": _load(),
            "imu_step_us": {"mean": float(np.mean(imu_us)), "p95": q(imu_us, 95)},
            "imu_rate_hz": float(rt.trial.rate_hz)}


def _load():
    try:
        return os.getloadavg()[0]
    except (OSError, AttributeError):
        return None
