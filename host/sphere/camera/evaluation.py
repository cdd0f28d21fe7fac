"""The hybrid tracker on rendered BROAD trials, side by side with the colour-blob method of the
PlayStation Move's open trackers, camera-only, camera + Kalman filter (no IMU) and IMU-only; the figures of issue 16 (RMSE lateral and depth, jitter at rest, latency, loss of
the ball, output rate, time per frame).

Time: every event carries the host's clock. IMU sample k (time t_k on the trial's clock) reaches the
host IMU_LATENCY_S later; a frame reaches it at its arrival time and is stamped with arrival − the
camera's nominal latency (the host cannot know the true exposure time). Every method's output is
compared with where the ball *is* at the moment of the output, so latency counts as error.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from sphere import broad
from sphere import quaternion as quat
from sphere.camera.detect import BallDetector, blob_position
from sphere.camera.live import FrameClock, hint_from
from sphere.camera.marker import MarkerDetector
from sphere.camera.trials import RenderedTrial
from sphere.chips import STANDARD_GRAVITY_M_S2
from sphere.fusion.hybrid import CameraImuTracker, _rot

IMU_LATENCY_S = 0.004  # serial link: a 40-byte frame at 115200 Bd plus the host's read
NOMINAL_CAMERA_LATENCY_S = 0.040  # what the host assumes from the middle of the exposure to arrival
METHODS = ("blob", "camera", "camera-kf", "imu", "hybrid")


@dataclass
class Run:
    t_out: np.ndarray  # host time of each output (IMU rate)
    truth: np.ndarray  # (N, 3) where the ball is at t_out, camera frame
    est: dict  # method → (N, 3), NaN before a method has an estimate
    frames: int
    detected: int
    per_frame_ms: np.ndarray  # detection + fusion, per frame
    detect_ms: np.ndarray
    stats: dict
    alignment_error_deg: float | None
    rest: np.ndarray  # (N,) bool: BROAD's movement flag off
    losses: list = field(default_factory=list)  # (t0, t1) of full occlusions
    alignment_ready_s: float | None = None  # when the hybrid's camera-to-earth rotation formed
    orientation: dict | None = None  # with a marker on the shell: orientation errors (°)
    fixes: list = field(default_factory=list)  # (t_mid, error of the fix against the truth (m), the gate's verdict)


def run(rt: RenderedTrial, hue_deg: float = 120.0, tracker: dict | None = None) -> Run:
    """Every method on a rendered trial; ``tracker``: settings of the hybrid's CameraImuTracker (to choose them)."""
    cam = rt.scene.camera
    det = BallDetector(cam, hue_deg=hue_deg, radius_m=rt.scene.radius_m)
    mdet = None
    if rt.scene.marker is not None:
        mdet = MarkerDetector(cam, rt.scene.marker, rt.scene.radius_m)
    markers = 0
    n_imu = len(rt.t)
    R_host = np.full((n_imu, 3, 3), np.nan)  # the host filter's orientation through the alignment
    R_hyb = np.full((n_imu, 3, 3), np.nan)  # the same with the marker's heading correction
    hyb = CameraImuTracker(**(tracker or {}))
    ckf = CameraImuTracker(use_imu=False)
    tr = rt.trial
    n = len(rt.t)
    t_imu_host = rt.t + IMU_LATENCY_S
    est = {m: np.full((n, 3), np.nan) for m in METHODS}
    frames = rt.frames()
    start, mid, arrival, exposure = rt.frame_times()
    order = np.argsort(arrival)
    next_frame = 0
    last_cam = None
    hint = None
    per_frame, det_ms, detected = [], [], 0
    fixes = []
    last_blob, blob_hint = None, None
    t_ready = None
    frame_iter = {k: None for k in range(len(start))}
    pending = {}
    clock = FrameClock(NOMINAL_CAMERA_LATENCY_S, 1.0 / rt.scene.fps)
    gyro = tr.gyr_rad_s - gyro_bias(rt)  # the rates as the daemon gives them to the tracker: bias removed
    for i in range(n):
        # frames that arrived before this IMU sample reaches the host
        while next_frame < len(order) and arrival[order[next_frame]] <= t_imu_host[i]:
            k = order[next_frame]
            next_frame += 1
            while k not in pending:
                f = next(frames)
                pending[f.index] = f
            f = pending.pop(k)
            t0 = time.perf_counter()
            t_exp = clock(f.t_arrival)
            hint = hint_from(hyb, cam, t_exp, rt.scene.radius_m, hint)
            d = det.detect(f.image, hint)
            t1 = time.perf_counter()
            if d is not None:
                detected += 1
                verdict = hyb.camera(t_exp, d.center_cam, d.cov)
                fixes.append((f.t_mid, float(np.linalg.norm(d.center_cam - f.truth_cam)), verdict))
                if mdet is not None:
                    pose = mdet.detect(f.image, d.center_px, d.radius_px, d.center_cam)
                    if pose is not None:
                        markers += 1
                        hyb.marker(t_exp, pose.R_cam_body)
                last_cam = d.center_cam
                hint = (d.center_px, d.radius_px)
                ckf.camera(t_exp, d.center_cam, d.cov)
            else:
                hint = None
            t2 = time.perf_counter()
            per_frame.append(1000 * (t2 - t0))
            det_ms.append(1000 * (t1 - t0))
            if d is not None:  # the same region as ours (the largest one may be something else): what
                blob_hint = (d.center_px, d.radius_px)  # differs is only how the position is measured
            b = blob_position(f.image, cam, hue_deg, rt.scene.radius_m, blob_hint)
            if b is not None:
                last_blob = b
                blob_hint = (cam.project(b[None])[0], cam.fx * rt.scene.radius_m / b[2]) if b[2] > 0.05 else None
            else:
                blob_hint = None
        q, a = rt.q_host_enu[i], tr.acc_m_s2[i]
        if t_ready is None and hyb.alignment.ready:
            t_ready = float(t_imu_host[i])
        p = hyb.imu(rt.t[i], q, a, lead_s=IMU_LATENCY_S, gyro_rad_s=gyro[i])
        if p is not None:
            est["hybrid"][i] = p
        if mdet is not None and hyb.alignment.ready:
            R_host[i] = hyb.alignment.R @ _rot(q)
            R_hyb[i] = hyb.orientation(q)
        p = ckf.imu(rt.t[i], q, a, lead_s=IMU_LATENCY_S, gyro_rad_s=gyro[i])
        if p is not None:
            est["camera-kf"][i] = p
        if last_cam is not None:
            est["camera"][i] = last_cam
        if last_blob is not None:
            est["blob"][i] = last_blob
    del frame_iter
    est["imu"] = _imu_only(rt, hyb)
    truth = rt.truth_cam(t_imu_host)
    R_true = _true_alignment(rt)
    align_err = None
    if hyb.alignment.R is not None and R_true is not None:
        dR = hyb.alignment.R @ R_true.T
        align_err = float(np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1))))
    losses = [(o.t0, o.t1) for o in rt.scene.occlusions if o.cover >= 1.0]
    run_ = Run(t_imu_host, truth, est, len(start), detected, np.array(per_frame), np.array(det_ms),
               dict(hyb.stats), align_err, ~tr.movement.astype(bool), losses, t_ready, fixes=fixes)
    if mdet is not None:
        run_.orientation = _orientation_errors(rt, R_host, R_hyb, markers)
    return run_


def gyro_bias(rt: RenderedTrial) -> np.ndarray:
    """The gyro's bias (rad/s) as a device learns it while it lies still: the mean rate over the trial's rest
    samples before the stretch (BROAD's trials start at rest); zeros without any."""
    full = broad.load_trial(broad.find_trial(rt.name))
    a = int(round(rt.start_s * full.rate_hz))
    rest = ~full.movement[:a].astype(bool)
    return full.gyr_rad_s[:a][rest].mean(axis=0) if rest.sum() >= 10 else np.zeros(3)


def _orientation_errors(rt: RenderedTrial, R_host, R_hyb, markers: int) -> dict:
    """RMS angle (°) between the ball's true orientation in the camera frame and the host filter's (through
    the estimated alignment), without and with the marker's heading correction."""
    R_true = np.einsum("ij,njk->nik", rt.scene.R_wc.T, np.array([_rot(q) if np.all(np.isfinite(q)) else
                                                                  np.full((3, 3), np.nan) for q in rt.trial.opt_quat]))
    out = {"frames_with_marker": markers}
    for name, R in (("host_filter", R_host), ("with_marker", R_hyb)):
        ok = np.all(np.isfinite(R), axis=(1, 2)) & np.all(np.isfinite(R_true), axis=(1, 2))
        if ok.sum() < 10:
            out[name + "_rms_deg"] = None
            continue
        tr = np.einsum("nij,nij->n", R[ok], R_true[ok])
        ang = np.degrees(np.arccos(np.clip((tr - 1) / 2, -1, 1)))
        out[name + "_rms_deg"] = float(np.sqrt(np.mean(ang * ang)))
    return out


def _true_alignment(rt: RenderedTrial):
    """Earth (the host filter's ENU) → camera, from the scene and the filter's heading offset against BROAD's
    reference (only to score the estimate; the tracker never sees it)."""
    ok = np.all(np.isfinite(rt.trial.opt_quat), axis=1)
    if not ok.any():
        return None
    # R_ref←host: the mean rotation taking the host's earth frame to the optical one
    e = quat.multiply(quat.normalize(rt.trial.opt_quat[ok]), quat.conjugate(quat.normalize(rt.q_host_enu[ok])))
    e = e * np.sign(e[:, :1] + 1e-300)
    m = e.mean(axis=0)
    return rt.scene.R_wc.T @ _rot(m / np.linalg.norm(m))


def _imu_only(rt: RenderedTrial, hyb: CameraImuTracker) -> np.ndarray:
    """Dead reckoning from the true position and velocity at the first frame, with the hybrid's final
    alignment (or the true one if it never formed) and the same gravity removal: the IMU alone."""
    R = hyb.alignment.R if hyb.alignment.R is not None else _true_alignment(rt)
    t = rt.t
    n = len(t)
    out = np.full((n, 3), np.nan)
    k0 = int(np.searchsorted(t, 0.1))
    if R is None or k0 + 2 >= n:
        return out
    truth = rt.truth_cam(t)
    p = truth[k0].copy()
    v = (truth[k0 + 1] - truth[k0 - 1]) / (t[k0 + 1] - t[k0 - 1])
    g = STANDARD_GRAVITY_M_S2
    f = np.einsum("nij,nj->ni", np.array([_rot(q) for q in rt.q_host_enu]), rt.trial.acc_m_s2)
    for i in range(k0, n):
        if i > k0:
            dt = t[i] - t[i - 1]
            a = R @ (f[i] - np.array([0.0, 0.0, g]))
            p = p + v * dt + 0.5 * a * dt * dt
            v = v + a * dt
        out[i] = p
    return out


# -- the figures -----------------------------------------------------------------------------------------

def _lat_depth(err):
    lat = np.sqrt(np.mean(err[:, 0] ** 2 + err[:, 1] ** 2) / 2)  # per lateral axis
    return float(lat), float(np.sqrt(np.mean(err[:, 2] ** 2)))


def latency_ms(t, est, truth_fn, max_ms: int = 200, min_ms: int = -50) -> float | None:
    """The lag that best lines the output up with the truth (ms; negative: the output runs ahead)."""
    ok = np.all(np.isfinite(est), axis=1)
    if ok.sum() < 50:
        return None
    best = None
    for lag in range(min_ms, max_ms + 1):
        e = est[ok] - truth_fn(t[ok] - lag / 1000.0)
        r = float(np.mean(np.sum(e * e, axis=1)))
        if best is None or r < best[1]:
            best = (lag, r)
    return float(best[0])


def figures(r: Run, rt: RenderedTrial) -> dict:
    out = {m: method_figures(r, rt, r.est[m]) for m in METHODS}
    out["hybrid"]["output_rate_hz"] = float(1.0 / np.median(np.diff(r.t_out)))
    out["camera"].update(fix_figures(r.fixes))
    out["hybrid"]["alignment_ready_s"] = r.alignment_ready_s
    return out


#: the gate's verdicts that let a fix into the output
USED = ("init", "accepted", "reacquired")


def fix_figures(fixes, off_m: float = 0.05) -> dict:
    """The camera's own fixes (each against the truth at its exposure): how many are more than ``off_m`` off,
    before the hybrid's gate and after it (those it used), and the worst of each."""
    err = np.array([e for _, e, _ in fixes]) if fixes else np.zeros(0)
    used = np.array([v in USED for _, _, v in fixes], bool) if fixes else np.zeros(0, bool)
    return {"fixes": int(len(err)), "fixes_used": int(used.sum()),
            "fixes_over_50mm": int((err > off_m).sum()), "fixes_over_50mm_after_gate": int((err[used] > off_m).sum()),
            "worst_fix_m": float(err.max()) if len(err) else None,
            "worst_fix_after_gate_m": float(err[used].max()) if used.any() else None}


def method_figures(r: Run, rt: RenderedTrial, est: np.ndarray) -> dict:
    """The figures of one output ``est`` (N, 3) at the run's output times ``r.t_out``."""
    in_loss = np.zeros(len(r.t_out), bool)
    for a, b in r.losses:
        in_loss |= (r.t_out >= a) & (r.t_out < b + 0.5)
    moving = ~r.rest
    # the warm-up: until the hybrid has learnt how the camera stands (the same samples left out for every
    # method); the figures with it are kept as *_with_warmup
    warm = r.t_out < (r.alignment_ready_s if r.alignment_ready_s is not None else np.inf)
    e = est - r.truth
    ok = np.all(np.isfinite(e), axis=1)
    use = ok & ~in_loss & ~warm
    fig = {}
    if use.sum() >= 10:
        fig["rmse_lateral_m"], fig["rmse_depth_m"] = _lat_depth(e[use])
        fig["max_error_m"] = float(np.linalg.norm(e[use], axis=1).max())
    if (ok & ~in_loss).sum() >= 10:
        fig["rmse_lateral_with_warmup_m"], fig["rmse_depth_with_warmup_m"] = _lat_depth(e[ok & ~in_loss])
    jit = _jitter(r.t_out, e, ok & r.rest)
    if jit:
        fig["jitter_lateral_m"], fig["jitter_depth_m"] = jit
    fig["latency_ms"] = latency_ms(r.t_out[moving & ~warm], est[moving & ~warm], rt.truth_cam)
    fig["coverage"] = float(ok.mean())
    steady = float(np.sqrt(np.mean(np.sum(e[use] ** 2, axis=1)))) if use.sum() >= 10 else 0.0
    fig["losses"] = [_loss(r.t_out, e, a, b, max(0.01, 2.0 * steady)) for a, b in r.losses]
    return fig


def _jitter(t, e, rest, min_s: float = 1.0, trim_s: float = 0.3):
    """RMS over rest stretches (≥ 1 s, 0.3 s trimmed at each end) of each axis' standard deviation of the
    error: the output's wobble while the ball is still, without its constant offset."""
    idx = np.nonzero(rest)[0]
    if not len(idx):
        return None
    runs = np.split(idx, np.nonzero(np.diff(idx) > 1)[0] + 1)
    sds = []
    for run_ in runs:
        tt = t[run_]
        if tt[-1] - tt[0] < min_s:
            continue
        keep = run_[(tt > tt[0] + trim_s) & (tt < tt[-1] - trim_s)]
        if len(keep) > 20:
            sds.append(e[keep].std(axis=0))
    if not sds:
        return None
    s = np.sqrt(np.mean(np.square(sds), axis=0))
    return float(np.sqrt((s[0] ** 2 + s[1] ** 2) / 2)), float(s[2])


def _loss(t, e, t0, t1, recovered_m: float = 0.01, hold_s: float = 0.2):
    """Error when the ball comes back (at t1), and how long until the error stays under ``recovered_m`` (1 cm
    or twice the method's own RMS error outside the loss, whichever is larger) for 0.2 s."""
    ok = np.all(np.isfinite(e), axis=1)
    norm = np.where(ok, np.linalg.norm(np.where(ok[:, None], e, 0.0), axis=1), np.inf)
    i1 = int(np.searchsorted(t, t1))
    if i1 >= len(t):
        return {"t0": t0, "t1": t1}
    res = {"t0": t0, "t1": t1, "error_at_return_m": float(norm[i1]) if np.isfinite(norm[i1]) else None,
           "recovered_below_m": recovered_m}
    good = norm < recovered_m
    for j in range(i1, len(t)):
        end = np.searchsorted(t, t[j] + hold_s)
        if end < len(t) and good[j:end].all():
            res["recovery_s"] = float(t[j] - t1)
            break
    else:
        res["recovery_s"] = None
    return res
