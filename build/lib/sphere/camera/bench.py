"""Time per frame of the camera pipeline on one core: detection + fusion at 640×480 (issue 16's ≤ 5 ms).

Frames are rendered first (not timed): a BROAD stretch as the virtual webcam sees it. Then each frame
goes through the detector (with the track's hint, as live) and the tracker's camera update (which
re-propagates the IMU samples since the exposure); the IMU samples between frames are timed apart.

Times are the thread's CPU time (``time.thread_time``), so other programs sharing the cores do not
inflate them; the wall-clock figures are printed beside them.
"""

from __future__ import annotations

import time

import numpy as np


def run(trial: str = "10", start_s: float = 40.0, seconds: float = 5.0, distance_m: float = 1.0) -> dict:
    import cv2

    from sphere.camera import trials
    from sphere.camera.detect import BallDetector
    from sphere.camera.evaluation import NOMINAL_CAMERA_LATENCY_S
    from sphere.camera.live import hint_from
    from sphere.fusion.hybrid import CameraImuTracker

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
            trk.imu(rt.t[i], rt.q_host_enu[i], rt.trial.acc_m_s2[i])
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
        import os

        return os.getloadavg()[0]
    except (OSError, AttributeError):
        return None
