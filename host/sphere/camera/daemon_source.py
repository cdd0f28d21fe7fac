"""The camera as sphere-mouse's second source: its ``[camera]`` settings and the object the daemon keeps.

Wiring (for the daemon; its ``PARAMS`` are the ``[camera]`` section, by one line in the daemon config's
``PARTS``):

    cam = CameraPosition.from_settings(cfg["camera"], log, source)  # None without [camera] source or a session
    ... on every RAW_SAMPLE, after the orientation filter:
    stream.position = cam.update(quat_sensor_to_earth, acc_m_s2, t_us, gyro_rad_s) if cam else None
    ... at exit: cam.close()

The position is the ball's centre in metres in the camera's frame (x right, y down, z out of the lens),
or None while it is unknown (no fix yet, or more than 2 s without one).

Time: frames are stamped on the host clock when they arrive; a sensor sample by its device time, mapped to
the host clock by the smallest delay seen so far (``SampleClock``: the host's read jitter drops out) less
the link's latency. A replayed session (``sphere-mouse --replay SESSION``) gives both the recorded host
times, so the replay meets frames and samples exactly as they met when recorded.
"""

from __future__ import annotations

import time

from sphere.errors import SphereError
from sphere.settings import Param


class CameraUnavailable(SphereError):
    """The camera named in [camera] cannot be used; the message says why and what to do."""


def _hue(v):
    return None if 0.0 <= v < 360.0 else "must be an angle in [0, 360) degrees (green 120, orange 25, blue 220)"


class SampleClock:
    """Device time (µs) → host time (s) of a sample's taking: device time + the smallest host-minus-device
    offset seen (the read least delayed by the host), less the link's latency. The offset may grow by
    ``drift`` (200 ppm: two crystals' tolerance) per second, so a device clock slower than the host's is
    followed; a restart of the device's time base (a jump back) starts it again."""

    def __init__(self, link_latency_s: float = 0.004, drift: float = 2e-4):
        self.link_latency_s, self.drift = link_latency_s, drift
        self.offset = None
        self._last_dev = None

    def __call__(self, t_dev_us, host_s: float) -> float:
        if t_dev_us is None:
            return host_s - self.link_latency_s
        dev = t_dev_us * 1e-6
        off = host_s - self.link_latency_s - dev
        if self.offset is None or self._last_dev is None or dev < self._last_dev:
            self.offset = off
        else:
            self.offset = min(self.offset + self.drift * (dev - self._last_dev), off)
        self._last_dev = dev
        return dev + self.offset


class CameraPosition:
    NAME = "camera"
    PARAMS = {
        "source": Param("", doc="webcam index (0, 1 ...) or a video file; empty: no camera (position stays null)"),
        "camera_file": Param("", doc="intrinsics from `sphere camera calibrate`; empty: a typical 60° webcam"),
        "hue_deg": Param(120.0, doc="the ball's colour (hue, degrees)", check=_hue),
        "latency_ms": Param(40.0, doc="from the middle of a frame's exposure to its arrival, on average", lo=0.0, hi=500.0,
                            unit="ms"),
    }

    def __init__(self, live, clock=time.perf_counter):
        self.live = live
        self.clock = clock  # the daemon's sources stamp arrivals with time.perf_counter
        self.sample_clock = SampleClock(live.lead_s)

    @classmethod
    def from_settings(cls, s, log=None, source=None) -> "CameraPosition | None":
        """From the [camera] settings; None when no camera is named. A replayed session (``source.session``)
        brings its own video, played on the replay's clock."""
        session = getattr(source, "session", None)
        if session is not None:
            if s.source:
                raise CameraUnavailable(f"[camera] source = {s.source!r}: a session brings its own video; replay "
                                        f"it without --camera (or replay its serial.bin alone with --camera)")
            return cls._session(s, log, source)
        if not s.source:
            return None
        try:
            import cv2  # noqa: F401  (optional: OpenCV, the camera extra; camera.live needs it only once it opens)
            from sphere.camera.live import CameraError, CameraSource, LiveTracker  # optional: OpenCV (the camera extra)
            from sphere.camera.model import Camera, CameraFileError  # optional: the camera (numpy, OpenCV)
        except ImportError as e:  # OpenCV missing
            raise CameraUnavailable(f"[camera] source = {s.source!r} needs OpenCV ({e}); install the camera extra: "
                              f"pip install -e '.[camera]'") from None
        try:
            cam = Camera.load(s.camera_file) if s.camera_file else None
            # a video file plays as a live camera would: paced at its frame rate, stamped on the host clock
            src = CameraSource(s.source, cam, hue_deg=s.hue_deg, latency_s=s.latency_ms / 1000.0,
                               realtime=True).start()
        except (CameraError, CameraFileError) as e:
            raise CameraUnavailable(f"[camera] {e}") from None
        if log:
            log(f"camera: {s.source} ({'calibrated: ' + s.camera_file if s.camera_file else 'uncalibrated'}), "
                f"ball hue {s.hue_deg:g}°")
        return cls(LiveTracker(src))

    @classmethod
    def _session(cls, s, log, source) -> "CameraPosition":
        from sphere.camera.live import CameraError, LiveTracker, SessionCamera  # optional: OpenCV (the camera extra)
        from sphere.camera.model import Camera, CameraFileError  # optional: the camera (numpy, OpenCV)

        session = source.session
        try:
            cam = Camera.load(s.camera_file) if s.camera_file else None
            src = SessionCamera(session.video_path, session.frame_times, cam, hue_deg=s.hue_deg,
                                latency_s=s.latency_ms / 1000.0)
        except (CameraError, CameraFileError) as e:
            raise CameraUnavailable(f"[camera] {e}") from None
        if log:
            log(f"camera: the session's video ({len(session.frame_times)} frames), ball hue {s.hue_deg:g}°")
        return cls(LiveTracker(src), clock=lambda: source.host_time_s)

    def update(self, q_sensor_to_earth, acc_m_s2, t_us=None, gyro_rad_s=None):
        """One sensor sample (device time ``t_us``) that arrived now: the ball's position (list of 3, m) at
        the moment of its arrival, or None. ``gyro_rad_s``: the sample's rates, bias removed (sensor axes)."""
        t = self.sample_clock(t_us, self.clock())
        p = self.live.sensor(t, q_sensor_to_earth, acc_m_s2, gyro_rad_s)
        return None if p is None else [float(v) for v in p]

    def watch_frames(self, on: bool) -> None:
        """An AR view is (not) watching: keep each frame's image and the pose at its exposure."""
        self.live.keep_frames = on
        self.live.source.keep_images = on

    def ar_frame(self) -> dict | None:
        """The newest frame for an AR view, once: its image (BGR), the camera's intrinsics, the ball's pose at the
        frame's exposure (position from the hybrid tracker, orientation from the sphere through the camera's
        alignment) and the detector's outline (None when the ball was not found in it)."""
        rec = self.live.ar_frame
        if rec is None:
            return None
        self.live.ar_frame = None
        f, verdict, p, R = rec
        cam = self.live.source.camera
        fix = f.fix
        return {"index": f.index, "image": f.image, "t_exposure_s": f.t_exposure,
                "camera": {"width": cam.width, "height": cam.height, "fx": cam.fx, "fy": cam.fy, "cx": cam.cx,
                           "cy": cam.cy, "dist": list(cam.dist)},
                "radius_m": self.live.source.radius_m,
                "position": None if p is None else [float(v) for v in p],
                "rotation": None if R is None else [[float(v) for v in row] for row in R],
                "outline": None if fix is None else {"centre": [float(v) for v in fix.center_px],
                                                      "radius": float(fix.radius_px), "verdict": verdict}}

    def diagnostics(self) -> dict:
        """What the camera and the tracker did so far (the 3-D stream's ``camera`` field)."""
        trk = self.live.tracker
        src = self.live.source
        return {"frames": src.frames, "found": src.found, **trk.stats, "alignment": trk.alignment.ready}

    def close(self) -> None:
        self.live.source.stop()
