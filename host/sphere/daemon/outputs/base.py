"""What every output has: the reference pose (the pose at start or at the last recentre), angles and
displacement relative to it, and a rate limit. Pure logic; the subclasses send."""

from __future__ import annotations

import math
import time

from sphere import quaternion as quat
from sphere.errors import SphereError


class OutputUnavailable(SphereError):
    """This output cannot start here; the message says why and what to do."""


def relative_euler_deg(q_ref, q) -> tuple[float, float, float]:
    """(yaw, pitch, roll) in degrees of ``q`` relative to ``q_ref`` (both sensor-to-earth), in the sphere's
    own frame at the reference pose (x towards the screen, y left, z up), Tait-Bryan z-y'-x'':
    yaw > 0 turned left, pitch > 0 nose (x) up, roll > 0 rolled right (right side down)."""
    w, x, y, z = quat.multiply(quat.conjugate(q_ref), q)
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    about_y = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    return math.degrees(yaw), -math.degrees(about_y), math.degrees(roll)


def relative_position(q_ref, p0, p) -> tuple[float, float, float]:
    """Earth-frame displacement ``p - p0`` (metres) in the reference pose's frame: (forward, left, up)."""
    d = [a - b for a, b in zip(p, p0)]
    fwd, left, up = quat.rotate(quat.conjugate(q_ref), d)
    return float(fwd), float(left), float(up)


class Output:
    """Base: keeps the reference pose and the last state; subclasses implement :meth:`send_pose`,
    and optionally :meth:`send_event`, :meth:`send_mode`, :meth:`close`."""

    NAME = "output"
    #: where a person looks at it (the 3-D page), or None
    url = None
    #: the camera's diagnostics, for an output that shows them (the 3-D page), or None
    camera = None
    #: someone watches the camera's frames through this output (the page's AR view): the daemon then keeps them
    frames_wanted = False

    def publish_frame(self, frame) -> None:
        """The camera's newest frame (sphere.camera.daemon_source.CameraPosition.ar_frame), for an output that
        shows it; most do not."""
    #: the settings of ``[outputs.NAME]`` (each output has ``enabled``); see sphere.settings
    PARAMS: dict = {}
    #: False: the output takes the orientation from :meth:`motion` and needs no smoothed pose (``orientation``
    #: is not called); when no output wants one and there is no 3-D stream, the daemon computes none.
    POSE = True

    def __init__(self, rate_hz: float = 100.0, clock=time.monotonic):
        self.period_s = 1.0 / rate_hz if rate_hz > 0 else 0.0
        self.clock = clock
        self.ref = None
        self.p0 = None
        self.quat = None
        self.sent = 0
        self._next = 0.0

    # -- from the daemon --
    def orientation(self, q, t_us=None, position=None) -> None:
        if q is None:
            return
        self.quat = tuple(float(v) for v in q)
        if self.ref is None:
            self.ref = self.quat
        if position is not None and self.p0 is None:
            self.p0 = tuple(float(v) for v in position)
        # paced by the device's clock when the packet has one (a replay at any speed sends what the sphere
        # would have sent), else by the wall clock
        now = t_us / 1e6 if t_us is not None else self.clock()
        if self._next - self.period_s <= now < self._next:
            return
        self._next = now + self.period_s
        angles = relative_euler_deg(self.ref, self.quat)
        moved = relative_position(self.ref, self.p0, position) if position is not None else None
        self.send_pose(self.quat, angles, moved, position, t_us)
        self.sent += 1

    def recentre(self) -> None:
        """The current pose (and position) become the reference."""
        self.ref = self.quat
        self.p0 = None

    def event(self, name: str, t_us=None) -> None:
        self.send_event(name, t_us)

    def link_lost(self) -> None:
        """The sphere's link is gone (unplugged, out of range, its battery flat). An output whose program acts on
        the last state by itself (a gamepad's stick held deflected keeps a game steering) lets go of it; the next
        pose after a reconnect is sent as usual."""

    def mode(self, name: str) -> None:
        self.send_mode(name)

    def motion(self, gyro_dps, accel_g, t_us=None, quat=None) -> None:
        """The sphere's bias-corrected angular rate (°/s) and acceleration (g, None when the accelerometer did
        not answer), sensor axes (x towards the screen, y left, z up at the reference pose), and its
        orientation as the fusion filter gives it (sensor to NWU, unsmoothed), once per sample. Outputs that
        speak rates (a 3-D mouse, a motion server) override it; :class:`Outputs` calls only those."""

    # -- to the program --
    def send_pose(self, q, angles_deg, moved_m, position_m, t_us) -> None:
        raise NotImplementedError

    def send_event(self, name: str, t_us) -> None:
        pass

    def send_mode(self, name: str) -> None:
        pass

    def close(self) -> None:
        pass
