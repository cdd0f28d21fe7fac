"""The camera as sphere-mouse's second source: its ``[camera]`` settings and the object the daemon keeps.

Wiring (for the daemon; its ``PARAMS`` are the ``[camera]`` section, by one line in the daemon config's
``PARTS``):

    cam = CameraPosition.from_settings(cfg["camera"], log)   # None when [camera] source is empty
    ... on every RAW_SAMPLE, after the orientation filter:
    stream.position = cam.update(quat_sensor_to_earth, acc_m_s2) if cam else None
    ... at exit: cam.close()

The position is the ball's centre in metres in the camera's frame (x right, y down, z out of the lens),
or None while it is unknown (no fix yet, or more than 2 s without one).
"""

from __future__ import annotations

import time

from sphere.settings import Param


class CameraUnavailable(Exception):
    """The camera named in [camera] cannot be used; the message says why and what to do."""


def _hue(v):
    return None if 0.0 <= v < 360.0 else "must be an angle in [0, 360) degrees (green 120, orange 25, blue 220)"


class CameraPosition:
    NAME = "camera"
    PARAMS = {
        "source": Param("", doc="webcam index (0, 1 ...) or a video file; empty: no camera (position stays null)"),
        "camera_file": Param("", doc="intrinsics from `sphere camera calibrate`; empty: a typical 60° webcam"),
        "hue_deg": Param(120.0, doc="the ball's colour (hue, degrees)", check=_hue),
        "latency_ms": Param(40.0, doc="from the middle of a frame's exposure to its arrival", lo=0.0, hi=500.0,
                            unit="ms"),
    }

    def __init__(self, live, clock=time.monotonic):
        self.live = live
        self.clock = clock

    @classmethod
    def from_settings(cls, s, log=None) -> "CameraPosition | None":
        """From the [camera] settings; None when no camera is named."""
        if not s.source:
            return None
        try:
            from sphere.camera.live import CameraError, CameraSource, LiveTracker
            from sphere.camera.model import Camera, CameraFileError
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

    def update(self, q_sensor_to_earth, acc_m_s2):
        """One sensor sample, now: the ball's position (list of 3, m) or None."""
        p = self.live.sensor(self.clock(), q_sensor_to_earth, acc_m_s2)
        return None if p is None else [float(v) for v in p]

    def close(self) -> None:
        self.live.source.stop()
