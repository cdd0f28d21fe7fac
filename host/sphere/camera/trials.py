"""BROAD trials as the virtual webcam sees them: the ball (8 cm) at the trial's optical positions
(``opt_pos``), a camera placed beside the motion, the trial's IMU samples for the sensor side.

The camera stands ``distance_m`` from the slice's mean position, at the same height + 10 cm, looking
at it horizontally (slightly down) from 45° off the main direction of the motion, so the ball moves both
across the image and in depth. BROAD's optical frame is the trial's ENU frame; the tracker is not told
how the camera stands: it estimates the camera-to-earth rotation itself.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.io import loadmat

from sphere import broad
from sphere.camera import render
from sphere.camera.model import Camera
from sphere.fusion import factory
from sphere.fusion.hybrid import _rot
from sphere.link import session
from sphere.protocol.framing import encode_frame
from sphere.sim import trace as T
from sphere.sim.trace import raw_packets


@dataclass
class Frame:
    index: int
    image: np.ndarray  # BGR uint8
    t_start: float  # exposure start (s, trial-slice time)
    t_mid: float  # middle of the exposure
    t_arrival: float  # when the host receives it
    exposure_s: float
    truth_cam: np.ndarray  # ball centre at t_mid, camera frame (m)


@dataclass
class RenderedTrial:
    name: str
    trial: broad.Trial  # the slice (IMU at trial.rate_hz)
    t: np.ndarray  # (N,) slice time of each IMU sample
    pos_world: np.ndarray  # (N, 3) ball centre (opt_pos, gaps interpolated)
    pos_valid: np.ndarray  # (N,) optical reference present
    scene: render.Scene
    q_host_enu: np.ndarray = field(default=None)  # (N, 4) the host filter's orientation (sensor → ENU)
    start_s: float = 0.0  # where the slice starts in the trial

    @property
    def duration_s(self) -> float:
        return float(len(self.t) / self.trial.rate_hz)

    def ball_world(self, t) -> np.ndarray:
        t = np.asarray(t, float)
        return np.stack([np.interp(t, self.t, self.pos_world[:, i]) for i in range(3)], axis=-1)

    def truth_cam(self, t) -> np.ndarray:
        return self.scene.to_camera(self.ball_world(t))

    def frame_times(self):
        return self.scene.frame_times(0.05, self.duration_s - 0.05)

    def frames(self):
        start, mid, arrival, exposure = self.frame_times()
        for k in range(len(start)):
            img = self.scene.render(start[k], exposure[k], self.ball_world, k)
            yield Frame(k, img, float(start[k]), float(mid[k]), float(arrival[k]), float(exposure[k]),
                        self.truth_cam(mid[k]))


def eval_occlusions() -> list:
    """`sphere hybrid-eval`'s hand: over a third of the ball at 3-4 s and over all of it at 7-8 s of a stretch."""
    return [render.Occlusion(3.0, 4.0, 0.35), render.Occlusion(7.0, 8.0, 1.0)]


def load_positions(path) -> np.ndarray:
    """BROAD's ``opt_pos`` (N, 3), metres (not part of :class:`sphere.broad.Trial`)."""
    d = loadmat(str(path), variable_names=["opt_pos"])
    if "opt_pos" not in d:
        raise ValueError(f"{path} has no opt_pos (optical positions); it is not a BROAD trial file")
    return np.asarray(d["opt_pos"], float)


def placement(pos: np.ndarray, distance_m: float, azimuth_off_deg: float = 45.0, height_m: float = 0.1):
    """(camera position, camera → world rotation) for a slice of positions."""
    ok = np.all(np.isfinite(pos), axis=1)
    m = pos[ok].mean(axis=0)
    xy = pos[ok, :2] - m[:2]
    w, v = np.linalg.eigh(xy.T @ xy)
    main = v[:, -1]
    a = np.radians(azimuth_off_deg)
    view = np.array([main[0] * np.cos(a) - main[1] * np.sin(a), main[0] * np.sin(a) + main[1] * np.cos(a), 0.0])
    cam = m - distance_m * view + np.array([0.0, 0.0, height_m])
    return cam, render.look_at(cam, m)


def rendered_trial(name: str, start_s: float, seconds: float, distance_m: float = 1.0, camera: Camera | None = None,
                   occlusions=(), hue_deg: float = 120.0, seed: int = 1, directory=None,
                   marker=None, jpeg_quality: int | None = None) -> RenderedTrial:
    """A slice of a BROAD trial, with the host filter's orientation (run from the trial's start, as the
    device would have been running) and the virtual camera placed beside it."""
    path = broad.find_trial(name, directory)
    full = broad.load_trial(path)
    total = len(full) / full.rate_hz
    if not (0 <= start_s < total) or seconds < 0.5 or start_s + seconds > total:
        raise ValueError(f"trial {full.name} is {total:.1f} s long; choose --start and --seconds inside it "
                         f"(at least 0.5 s)")
    pos = load_positions(path)
    a = int(round(start_s * full.rate_hz))
    b = a + int(round(seconds * full.rate_hz))
    f = factory.make("sphere", full.dt_s, full.acc_m_s2[0], full.mag_uT[0])
    q = f.update_batch(full.gyr_rad_s[:b], full.acc_m_s2[:b], full.mag_uT[:b], full.dt_s)[a:b]
    sl = full.seconds(start_s, seconds)
    p = pos[a:b]
    valid = np.all(np.isfinite(p), axis=1)
    if valid.sum() < 0.8 * len(p):
        raise ValueError(f"trial {full.name} has optical positions for only {100 * valid.mean():.0f} % of "
                         f"{start_s:g}-{start_s + seconds:g} s; choose another stretch")
    t = np.arange(len(p)) / full.rate_hz
    pf = np.stack([np.interp(t, t[valid], p[valid, i]) for i in range(3)], axis=1)
    cam_pos, R_wc = placement(pf, distance_m)
    body = None
    if marker is not None:  # the marker turns with the sensor: BROAD's optical orientation, gaps held

        qo = sl.opt_quat.copy()
        good = np.all(np.isfinite(qo), axis=1)
        if not good.any():
            raise ValueError(f"trial {full.name} has no optical orientation in this stretch for the marker")
        idx = np.maximum.accumulate(np.where(good, np.arange(len(qo)), 0))
        idx[: np.argmax(good)] = np.argmax(good)
        qo = qo[idx]

        def body(tt, _q=qo, _rate=full.rate_hz):
            return _rot(_q[int(np.clip(round(tt * _rate), 0, len(_q) - 1))])

        if marker.face == "auto":  # on the face of the sensor that is turned to the camera most of the time

            view = R_wc[:, 2]  # the camera's optical axis in the world
            faces = {f"{sg}{ax}": 0.0 for sg in "+-" for ax in "xyz"}
            for k in range(0, len(qo), 10):
                Rb = _rot(qo[k])
                for f in faces:
                    v = Rb[:, "xyz".index(f[1])] * (1 if f[0] == "+" else -1)
                    faces[f] += float(-v @ view > 0.5)
            marker = replace(marker, face=max(faces, key=faces.get))
    scene = render.Scene(camera or Camera.webcam(), R_wc, cam_pos, hue_deg=hue_deg, seed=seed,
                         occlusions=list(occlusions), marker=marker, body_rotation=body, jpeg_quality=jpeg_quality)
    return RenderedTrial(full.name, sl, t, pf, valid, scene, q, start_s)


#: a serial frame reaches the host this long after the sample is taken (hybrid-eval's IMU latency)
SESSION_IMU_LATENCY_S = 0.004


def write_session(rt: RenderedTrial, folder, lead_s: float | None = None, directory=None) -> dict:
    """A recorded session (:mod:`sphere.link.session`) of a rendered trial, as `sphere capture --camera` would record
    it: the trial's IMU as the sphere sends it (RAW_SAMPLE frames in the chips' units and rates, from
    ``lead_s`` before the stretch — by default from the trial's start, as the host filter of `sphere
    hybrid-eval` runs, a sphere switched on before the camera), each frame's bytes arriving 4 ms after the
    sample; the rendered frames at their arrival times.

    Returns the time bases: ``{"slice_t0_host_s": ...}``, the session time of the stretch's t = 0 (stretch
    time = session time − it; the sample's device time t_us = (slice time + lead_s + 1) · 10⁶)."""
    full = broad.load_trial(broad.find_trial(rt.name, directory))
    lead = rt.start_s if lead_s is None else min(lead_s, rt.start_s)
    motion = T.from_broad(full, rt.start_s - lead, rt.duration_s + lead)
    cam = rt.scene.camera
    with session.SessionWriter(folder, cam.width, cam.height, rt.scene.fps,
                               extra={"rendered": {"trial": rt.name, "start_s": rt.start_s, "lead_s": lead}}) as w:
        frames = rt.frames()
        pending = next(frames, None)
        for seq, (t_us, packet) in enumerate(raw_packets(motion)):
            t_host = t_us * 1e-6 - 1.0 + SESSION_IMU_LATENCY_S  # raw_packets' device time starts at 1 s
            while pending is not None and pending.t_arrival + lead <= t_host:
                w.write_frame(pending.image, pending.t_arrival + lead)
                pending = next(frames, None)
            w.write_serial(encode_frame(packet, seq & 0xFF), t_host)
        while pending is not None:
            w.write_frame(pending.image, pending.t_arrival + lead)
            pending = next(frames, None)
    return {"slice_t0_host_s": lead, "lead_s": lead}
