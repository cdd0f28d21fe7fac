"""The camera as a live source: a webcam (by index) or a video file read in a thread, the ball found in
each frame, each fix stamped with its exposure time on the host's clock.

This is the piece a daemon plugs in beside its serial source: ``CameraSource.start()``, then, on every
sensor sample, ``LiveTracker.sensor(t, q, acc)`` → the ball's position (camera frame, m) or None. Frames
are stamped when they arrive (``time.monotonic()``) and their exposure is taken to be ``latency_s``
earlier; for a video file the stamps are the file's frame times from the start (or arrival times given
with it), or, with ``realtime=True``, the file is paced at its frame rate and stamped by the clock.
"""

from __future__ import annotations

import queue
import threading
import time
from dataclasses import dataclass

import numpy as np

from sphere.camera.detect import BallDetector
from sphere.camera.model import Camera
from sphere.fusion.hybrid import CameraImuTracker


class CameraError(RuntimeError):
    """The camera cannot be used (one line: what was wrong, what to do)."""


@dataclass
class Fix:
    index: int  # frame number from the start
    t_arrival: float  # host clock (s)
    t_exposure: float
    center_cam: np.ndarray
    cov: np.ndarray
    center_px: np.ndarray
    radius_px: float


def hint_from(tracker, camera, t_exposure: float, radius_m: float, last=None):
    """Where to look in a frame: the tracker's position at its exposure time, projected; else the last fix."""
    p = tracker.position_at(t_exposure) if tracker.x is not None else None
    if p is not None and p[2] > 0.1:
        c = camera.project(p[None])[0]
        if np.all(np.isfinite(c)):
            return (c, camera.fx * radius_m / p[2])
    return last


class CameraSource:
    def __init__(self, spec, camera: Camera | None = None, hue_deg: float = 120.0, radius_m: float = 0.04,
                 latency_s: float = 0.040, realtime: bool | None = None, clock=time.monotonic,
                 arrival_times=None):
        self.spec = spec
        self.camera = camera
        self.hue_deg, self.radius_m = hue_deg, radius_m
        self.latency_s = latency_s
        # a webcam is stamped by the clock; a file by its frame times (or by the arrival times given, e.g.
        # the .csv that `sphere camera render` writes beside its video), unless realtime is asked for
        self.realtime = str(spec).isdigit() if realtime is None else realtime
        self.arrival_times = None if arrival_times is None else np.asarray(arrival_times, float)
        self.clock = clock
        self.fixes: queue.Queue = queue.Queue()
        self.frames = 0
        self.found = 0
        self.error: str | None = None
        self._stop = threading.Event()
        self._thread = None
        self.hint_fn = None  # t_exposure ↦ (centre_px, radius_px) or None: where the tracker expects the ball

    def _open(self):
        import cv2

        src = int(self.spec) if str(self.spec).isdigit() else str(self.spec)
        cap = cv2.VideoCapture(src)
        if not cap.isOpened():
            what = f"camera {src}" if isinstance(src, int) else f"video file {src}"
            raise CameraError(f"cannot open {what}; check the index (ls /dev/video*) or the file's path")
        return cap

    def start(self) -> "CameraSource":
        cap = self._open()
        w, h = int(cap.get(3)), int(cap.get(4))
        if self.camera is None:
            self.camera = Camera.webcam(w, h)  # uncalibrated: a typical webcam's field of view
        elif (self.camera.width, self.camera.height) != (w, h):
            cap.release()
            raise CameraError(f"the camera file is for {self.camera.width}x{self.camera.height}, the camera gives "
                              f"{w}x{h}; calibrate this mode with `sphere camera calibrate`")
        self._fps = cap.get(5) or 30.0
        self._thread = threading.Thread(target=self._run, args=(cap,), daemon=True, name="sphere-camera")
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _run(self, cap) -> None:
        det = BallDetector(self.camera, hue_deg=self.hue_deg, radius_m=self.radius_m)
        t0 = self.clock()
        last = None
        try:
            while not self._stop.is_set():
                ok, frame = cap.read()
                if not ok:
                    break
                if self.realtime:
                    t_arr = self.clock()
                    if not str(self.spec).isdigit():  # a file: pace it at its frame rate
                        due = t0 + (self.frames + 1) / self._fps
                        if due > t_arr:
                            time.sleep(due - t_arr)
                        t_arr = self.clock()
                elif self.arrival_times is not None:
                    if self.frames >= len(self.arrival_times):
                        break
                    t_arr = float(self.arrival_times[self.frames])
                else:
                    t_arr = (self.frames + 1) / self._fps + self.latency_s
                self.frames += 1
                t_exp = t_arr - self.latency_s
                hint = self.hint_fn(t_exp) if self.hint_fn is not None else None
                d = det.detect(frame, hint or last)
                if d is None:
                    last = None
                    continue
                self.found += 1
                last = (d.center_px, d.radius_px)
                self.fixes.put(Fix(self.frames - 1, t_arr, t_exp, d.center_cam, d.cov, d.center_px, d.radius_px))
        except Exception as e:  # the thread must say why it stopped, not die silently
            self.error = f"{type(e).__name__}: {e}"
        finally:
            cap.release()

    def poll(self) -> list[Fix]:
        out = []
        while True:
            try:
                out.append(self.fixes.get_nowait())
            except queue.Empty:
                return out


class LiveTracker:
    """Sensor samples in, the ball's position out, camera fixes folded in as they come."""

    def __init__(self, source: CameraSource, lead_s: float = 0.004):
        self.source = source
        self.tracker = CameraImuTracker()
        self.lead_s = lead_s
        self._pending: list[Fix] = []
        source.hint_fn = self._hint

    def _hint(self, t_exposure):
        return hint_from(self.tracker, self.source.camera, t_exposure, self.source.radius_m)

    def sensor(self, t: float, q_sensor_to_earth, acc_sensor):
        """One sensor sample (host clock): the position (camera frame, m) or None while unknown."""
        self._pending += self.source.poll()
        due = [f for f in self._pending if f.t_arrival <= t]  # (a file read ahead of time waits its turn)
        if due:
            self._pending = [f for f in self._pending if f.t_arrival > t]
            for f in sorted(due, key=lambda f: f.t_exposure):
                self.tracker.camera(f.t_exposure, f.center_cam, f.cov)
        return self.tracker.imu(t, q_sensor_to_earth, acc_sensor, lead_s=self.lead_s)
