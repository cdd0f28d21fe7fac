"""The camera as a live source: a webcam (by index) or a video file read in a thread, the ball found in
each frame, each fix stamped with its exposure time on the host's clock.

This is the piece a daemon plugs in beside its serial source: ``CameraSource.start()``, then, on every
sensor sample, ``LiveTracker.sensor(t, q, acc, gyro)`` → the ball's position (camera frame, m) or None. Frames
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
from sphere.errors import SphereError
from sphere.fusion.hybrid import CameraImuTracker


class CameraError(SphereError, RuntimeError):
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


@dataclass
class Frame:
    """One frame as the camera delivered it: the fix found in it (None without the ball) and, when an AR view
    is watching, the image itself (BGR)."""

    index: int
    t_arrival: float
    t_exposure: float
    fix: Fix | None
    image: np.ndarray | None = None


def hint_from(tracker, camera, t_exposure: float, radius_m: float, last=None):
    """Where to look in a frame: the tracker's position at its exposure time, projected; else the last fix."""
    p = tracker.position_at(t_exposure) if tracker.x is not None else None
    if p is not None and p[2] > 0.1:
        c = camera.project(p[None])[0]
        if np.all(np.isfinite(c)):
            return (c, camera.fx * radius_m / p[2])
    return last


class FrameClock:
    """A frame's arrival (host clock) → the middle of its exposure. A camera exposes its frames on its own
    regular clock, while the USB transfer and the decoding delay each arrival by a varying amount, only ever
    more than the least: on the virtual camera 35 ms + an exponential tail of mean 5 ms, so arrival − 40 ms
    misplaces single frames by up to 20 ms (30 mm at 1.5 m/s). The arrivals are fitted to a line over the frame
    numbers (the camera's period; a frame the camera dropped counts by the gap it leaves) over the last
    ``window`` frames, and a frame's exposure is the line's time for it less the mean latency (``latency_s``,
    `[camera] latency_ms`): the per-frame delay drops out (on hybrid-eval's frames 1.4 ms error left, worst
    5.3 ms; 4.7, worst 21, before). A frame the line cannot place (the camera paused or changed its rate)
    starts the fit again."""

    def __init__(self, latency_s: float, period_s: float | None = None, window: int = 300, min_frames: int = 10):
        self.latency_s = latency_s
        self.period_s = period_s or 1.0 / 30.0
        self.window, self.min_frames = window, min_frames
        self._n: list[int] = []
        self._t: list[float] = []
        self._line = None  # (time of frame 0, period)

    def __call__(self, t_arrival: float) -> float:
        n = 0
        if self._t:
            t0, period = self._line or (self._t[-1] - self.period_s * self._n[-1], self.period_s)
            # a late arrival is usual, an early one is not: a frame up to 0.8 periods behind the line (27 ms at
            # 30 fps) is still the next one, 0.2 periods ahead of it the one after
            x = (t_arrival - t0) / period - self._n[-1]
            if not (0.2 < x <= 8.0):  # the camera paused, restarted or changed its rate: start again
                self._n.clear()
                self._t.clear()
                self._line = None
            else:
                n = self._n[-1] + max(1, int(np.floor(x + 0.2)))
        self._n.append(n)
        self._t.append(t_arrival)
        if len(self._t) > self.window:
            del self._n[0], self._t[0]
        if len(self._t) < self.min_frames:
            return t_arrival - self.latency_s
        k = np.asarray(self._n, float)
        slope, t0 = np.polyfit(k, np.asarray(self._t), 1)
        self._line = (float(t0), float(slope))
        return float(t0 + slope * n) - self.latency_s


class FrameDetector:
    """The ball in each frame of a stream, as a live system looks for it: where the tracker expects it at the
    frame's exposure time (``hint_fn``), else around the last fix, else the whole frame."""

    def __init__(self, camera: Camera, hue_deg: float, radius_m: float, latency_s: float,
                 period_s: float | None = None):
        self.detector = BallDetector(camera, hue_deg=hue_deg, radius_m=radius_m)
        self.latency_s = latency_s
        self.clock = FrameClock(latency_s, period_s)
        self.hint_fn = None  # t_exposure ↦ (centre_px, radius_px) or None
        self.last = None
        self.frames = 0
        self.found = 0
        self.keep_images = False

    def __call__(self, index: int, image, t_arrival: float) -> Frame:
        t_exp = self.clock(t_arrival)
        hint = self.hint_fn(t_exp) if self.hint_fn is not None else None
        d = self.detector.detect(image, hint or self.last)
        self.frames += 1
        fix = None
        if d is None:
            self.last = None
        else:
            self.found += 1
            self.last = (d.center_px, d.radius_px)
            fix = Fix(index, t_arrival, t_exp, d.center_cam, d.cov, d.center_px, d.radius_px)
        return Frame(index, t_arrival, t_exp, fix, image if self.keep_images else None)


class CameraSource:
    def __init__(self, spec, camera: Camera | None = None, hue_deg: float = 120.0, radius_m: float = 0.04,
                 latency_s: float = 0.040, realtime: bool | None = None, clock=time.perf_counter,
                 arrival_times=None, detect: bool = True):
        self.spec = spec
        self.detect = detect  # False: only read and stamp the frames (for ``on_frame``)
        self.camera = camera
        self.hue_deg, self.radius_m = hue_deg, radius_m
        self.latency_s = latency_s
        # a webcam is stamped by the clock; a file by its frame times (or by the arrival times given, e.g.
        # the .csv that `sphere camera render` writes beside its video), unless realtime is asked for
        self.realtime = str(spec).isdigit() if realtime is None else realtime
        self.arrival_times = None if arrival_times is None else np.asarray(arrival_times, float)
        self.clock = clock  # the daemon's: sphere.daemon.sources.base's arrival times are time.perf_counter
        self.fixes: queue.Queue = queue.Queue()  # Frame objects, found or not
        self.error: str | None = None
        self.keep_images = False  # set when an AR view wants the frames themselves
        self.on_frame = None  # image, t_arrival ↦ None: every frame as it arrives (`sphere capture --camera`)
        self._stop = threading.Event()
        self._thread = None
        self._detector = None
        self.hint_fn = None  # t_exposure ↦ (centre_px, radius_px) or None: where the tracker expects the ball

    @property
    def frames(self) -> int:
        return self._detector.frames if self._detector is not None else 0

    @property
    def found(self) -> int:
        return self._detector.found if self._detector is not None else 0

    def _open(self):
        import cv2  # optional dependency: the camera extra (OpenCV)

        src = int(self.spec) if str(self.spec).isdigit() else str(self.spec)
        level = cv2.utils.logging.getLogLevel()
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)  # our own line says what went wrong
        try:
            cap = cv2.VideoCapture(src)
        finally:
            cv2.utils.logging.setLogLevel(level)
        if not cap.isOpened():
            if isinstance(src, int) or src.startswith("/dev/"):
                what = f"camera {src}"
                hint = ("it is missing, busy in another program, or not readable by this user (the video group); "
                        "ls /dev/video* lists the cameras")
            else:
                what = f"video file {src}"
                hint = "check the file's path, or give a camera's index (ls /dev/video* lists them)"
            raise CameraError(f"cannot open {what}: {hint}")
        return cap

    def open(self) -> "CameraSource":
        """Opens the camera (CameraError when it cannot be used) without reading from it yet."""
        cap = self._open()
        w, h = int(cap.get(3)), int(cap.get(4))
        if self.camera is None:
            self.camera = Camera.webcam(w, h)  # uncalibrated: a typical webcam's field of view
        elif (self.camera.width, self.camera.height) != (w, h):
            cap.release()
            raise CameraError(f"the camera file is for {self.camera.width}x{self.camera.height}, the camera gives "
                              f"{w}x{h}; calibrate this mode with `sphere camera calibrate`")
        self._fps = cap.get(5) or 30.0
        self._cap = cap
        return self

    def release(self) -> None:
        """Closes a camera opened and not started."""
        if getattr(self, "_cap", None) is not None and self._thread is None:
            self._cap.release()

    @property
    def fps(self) -> float:
        return self._fps

    def start(self) -> "CameraSource":
        if getattr(self, "_cap", None) is None:
            self.open()
        self._detector = FrameDetector(self.camera, self.hue_deg, self.radius_m, self.latency_s, 1.0 / self._fps)
        self._thread = threading.Thread(target=self._run, args=(self._cap,), daemon=True, name="sphere-camera")
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
        det = self._detector
        t0 = self.clock()
        n = 0
        try:
            while not self._stop.is_set():
                ok, frame = cap.read()
                if not ok:
                    break
                if self.realtime:
                    t_arr = self.clock()
                    if not str(self.spec).isdigit():  # a file: pace it at its frame rate
                        due = t0 + (n + 1) / self._fps
                        if due > t_arr:
                            time.sleep(due - t_arr)
                        t_arr = self.clock()
                elif self.arrival_times is not None:
                    if n >= len(self.arrival_times):
                        break
                    t_arr = float(self.arrival_times[n])
                else:
                    t_arr = (n + 1) / self._fps + self.latency_s
                if self.on_frame is not None:
                    self.on_frame(frame, t_arr)
                if not self.detect:
                    n += 1
                    continue
                det.hint_fn = self.hint_fn
                det.keep_images = self.keep_images
                self.fixes.put(det(n, frame, t_arr))
                n += 1
        except Exception as e:  # the thread must say why it stopped, not die silently
            self.error = f"{type(e).__name__}: {e}"
        finally:
            cap.release()

    def poll_frames(self, t: float | None = None) -> list[Frame]:
        """Every frame processed since the last call (a live camera's thread decides what has arrived)."""
        out = []
        while True:
            try:
                out.append(self.fixes.get_nowait())
            except queue.Empty:
                return out

    def poll(self) -> list[Fix]:
        """The fixes found since the last call."""
        return [f.fix for f in self.poll_frames() if f.fix is not None]


class SessionCamera:
    """The video of a recorded session (:mod:`sphere.link.session`) as the camera: each frame is read and searched
    when the replay's clock reaches its recorded arrival time, in the caller's thread, so the replay is the
    same at any speed (as fast as possible included) and the tracker's hints are those it would have had."""

    def __init__(self, video_path, frame_times, camera: Camera | None = None, hue_deg: float = 120.0,
                 radius_m: float = 0.04, latency_s: float = 0.040):
        import cv2  # optional: OpenCV (the camera extra)

        self.path = str(video_path)
        self.times = list(frame_times)
        self.hue_deg, self.radius_m, self.latency_s = hue_deg, radius_m, latency_s
        self.error = None
        self.keep_images = False
        self.hint_fn = None
        self._cap = cv2.VideoCapture(self.path)
        if not self._cap.isOpened():
            raise CameraError(f"cannot open the session's video {self.path}")
        w, h = int(self._cap.get(3)), int(self._cap.get(4))
        if camera is None:
            camera = Camera.webcam(w, h)
        elif (camera.width, camera.height) != (w, h):
            raise CameraError(f"the camera file is for {camera.width}x{camera.height}, the session's video is {w}x{h}")
        self.camera = camera
        fps = self._cap.get(5)
        self._detector = FrameDetector(camera, hue_deg, radius_m, latency_s, 1.0 / fps if fps and fps > 0 else None)
        self._next = 0

    frames = CameraSource.frames
    found = CameraSource.found

    def start(self) -> "SessionCamera":
        return self

    @property
    def running(self) -> bool:
        return self._next < len(self.times)

    def stop(self) -> None:
        self._cap.release()

    def poll_frames(self, t: float | None = None) -> list[Frame]:
        out = []
        while self._next < len(self.times) and (t is None or self.times[self._next] <= t):
            ok, image = self._cap.read()
            if not ok:  # the video is shorter than its time file: the rest is not there
                self.error = f"{self.path} ends after {self._next} of {len(self.times)} frames"
                self._next = len(self.times)
                break
            self._detector.hint_fn = self.hint_fn
            self._detector.keep_images = self.keep_images
            out.append(self._detector(self._next, image, self.times[self._next]))
            self._next += 1
        return out

    def poll(self) -> list[Fix]:
        return [f.fix for f in self.poll_frames() if f.fix is not None]


class LiveTracker:
    """Sensor samples in, the ball's position out, camera fixes folded in as they come."""

    def __init__(self, source, lead_s: float = 0.004):
        self.source = source
        self.tracker = CameraImuTracker()
        self.lead_s = lead_s
        self._pending: list[Frame] = []
        self.keep_frames = False  # an AR view is watching: keep the newest frame with the pose drawn on it
        self.ar_frame = None  # (Frame, the gate's verdict, position at its exposure, body → camera or None)
        source.hint_fn = self._hint

    def _hint(self, t_exposure):
        return hint_from(self.tracker, self.source.camera, t_exposure, self.source.radius_m)

    def sensor(self, t: float, q_sensor_to_earth, acc_sensor, gyro_rad_s=None):
        """One sensor sample taken at ``t`` (host clock), arriving ``lead_s`` later (the link's latency): the
        frames that arrived by then are used, and the position (camera frame, m) at the arrival, when the
        output is used, is returned; None while it is unknown. ``gyro_rad_s``: its rates (bias removed)."""
        now = t + self.lead_s
        self._pending += self.source.poll_frames(now)
        due = [f for f in self._pending if f.t_arrival <= now]  # (a file read ahead of time waits its turn)
        if due:
            self._pending = [f for f in self._pending if f.t_arrival > now]
            for f in sorted(due, key=lambda f: f.t_exposure):
                status = None
                if f.fix is not None:
                    status = self.tracker.camera(f.t_exposure, f.fix.center_cam, f.fix.cov)
                if self.keep_frames:  # the pose at the frame's exposure, its stamp as the frame itself corrected it
                    shift = self.tracker.exposure_shift_s if status == "accepted" else 0.0
                    self.ar_frame = (f, status, *self.tracker.pose_at(f.t_exposure + shift))
        return self.tracker.imu(t, q_sensor_to_earth, acc_sensor, lead_s=self.lead_s, gyro_rad_s=gyro_rad_s)
