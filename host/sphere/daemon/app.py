"""The sphere-mouse daemon loop: source → motion → mode (pointer, tilt, 3-D) → backend, events → actions."""

from __future__ import annotations

import logging
import math
import os

from sphere.daemon.actions import Action, EventActions
from sphere.daemon.collector import BetweenBatches
from sphere.daemon.backends.pynput_backend import main_screen_size
from sphere.daemon.config import smoothing_params
from sphere.daemon.gyro_bias import GyroBias, RestHold
from sphere.daemon.motion import G_M_S2, MotionTracker
from sphere.daemon.pointer import PointerMapper, TiltMapper
from sphere.daemon.priority import LoopPriority
from sphere.protocol.packets import RAW_ACCEL_OK, RAW_GYRO_OK, RAW_GYRO_STALE, RAW_MAG_OK, RAW_TAP_ACTIVE
from sphere.protocol import Event, Hello, Orientation, RawSample, Status
from sphere.smoothing.pose import PoseFilter
from sphere.smoothing.registry import POSITION

DEFAULT_SCREEN_WIDTH_PX = 1920


def pose_filter(cfg) -> PoseFilter:
    """The daemon's pose filter from its config: ``stream.smoothing`` and its ``[smoothing.NAME]`` for the
    orientation, ``stream.position_smoothing`` and its ``[position_smoothing.NAME]`` for the position."""
    name, pname = cfg.stream.smoothing, cfg.stream.position_smoothing
    return PoseFilter(name, (pname, smoothing_params(cfg, pname, POSITION)), **smoothing_params(cfg, name))


def motion_tracker(cfg) -> MotionTracker:
    """The daemon's motion tracker (host orientation filter, gyro bias, rest hold) from its config."""
    g = cfg.gyro
    motion = MotionTracker(cfg.orientation.source, cfg.orientation.use_mag,
                           GyroBias(still_dps=g.still_dps, still_time_s=g.still_time_s, enabled=g.auto_bias,
                                    **cfg["gyro_bias"].as_dict()),
                           filter_name=cfg.orientation.filter, rest_hold=RestHold(**cfg["rest_hold"].as_dict()),
                           filter_settings=cfg.get)
    motion.defer = True  # handle() runs the deferred work after each sample's move
    return motion


BUTTONS = {"left_click": "left", "right_click": "right", "middle_click": "middle"}
logger = logging.getLogger("sphere.daemon")

#: RAW_SAMPLE flags (protocol/spec.md §4.2) of the sensors the status line reports when they stop answering.
SENSOR_FLAGS = (("accelerometer", RAW_ACCEL_OK), ("gyroscope", RAW_GYRO_OK), ("magnetometer", RAW_MAG_OK))
_SENSORS_OK = RAW_ACCEL_OK | RAW_GYRO_OK | RAW_MAG_OK
#: What the loop does for a request a signal handler made (handlers only set a flag).
REQUESTS = ("recentre", "pause", "stop")


def _desktop_size():
    """The X screen's size when an X display is reachable (uinput itself cannot know it); else None."""
    if not os.environ.get("DISPLAY"):
        return None
    try:
        return main_screen_size()
    except Exception:
        return None


class SphereMouse:
    """Owns the state of one running daemon. ``handle(DecodedPacket)`` is the whole per-packet work;
    ``run()`` drives it from the source until the source ends or :meth:`stop` is called."""

    def __init__(self, cfg, source, backend, stream=None, status=None, log=None, camera=None):
        self.cfg = cfg
        self.camera = camera  # sphere.camera.daemon_source.CameraPosition: the ball's position for the stream
        self._ar_watching = False  # a page's AR view asked for the camera's frames
        self.source = source
        self.backend = backend
        self.stream = stream
        self.status = status
        self.log = log or logger.info
        self.warn = log or logger.warning
        width = cfg.output.screen_width_px
        if not width:
            size = backend.screen_size()
            if size is None and backend.NAME == "uinput":
                size = _desktop_size()
            width = size[0] if size else DEFAULT_SCREEN_WIDTH_PX
        self.screen_width_px = width
        self.mapper = PointerMapper(cfg.pointer, width, smoothing_params(cfg, cfg.pointer.smoothing))
        self.pose = pose_filter(cfg)  # the pose the stream and every output get ([stream] smoothing)
        self.tilt = TiltMapper(cfg.tilt, cfg.pointer.invert_x, cfg.pointer.invert_y)
        self.motion = motion_tracker(cfg)
        self.actions = EventActions(cfg.events, cfg.freeze)
        self.modes = list(cfg.mode.cycle)
        if cfg.mode.start not in self.modes:
            self.modes.insert(0, cfg.mode.start)
        self.mode = cfg.mode.start
        self.paused = False
        self.battery_mv = 0
        self.now_us = None
        self.hello = None
        self.moves = 0
        self.clicks = 0
        self.mode_changes: list[str] = []
        self._generation = None
        self._connected = False  # the source's link as the loop last saw it (a lost one is told to the outputs)
        self._recentre_tilt = True
        self._stopped = False
        self._requests: list[str] = []
        self.sensor_flags = None  # the last RAW_SAMPLE's sensor bits (None: none since the last HELLO)
        self._sensors_reported = 0  # the sensors the log has said are missing (until it says they answer)
        self.sensors_missing: tuple[str, ...] = ()
        if stream is not None:
            stream.mode = self.mode
        # outputs that speak rates (a 3-D mouse, a motion server) get each sample's rate and acceleration
        self._publish_motion = getattr(stream, "publish_motion", None)
        #: the garbage collector, run between batches (after the move) while the loop runs
        self.collector = BetweenBatches()
        self.move_log = None  # sphere.daemon.move_log.MoveLog: each move's read and call times (--move-log)
        #: the loop's scheduling priority, raised while it reads a live source (sphere.daemon.priority)
        self.priority = LoopPriority(**cfg["priority"].as_dict())
        self.priority.on_demoted = lambda: self.request("demoted")

    # -- actions --
    def set_mode(self, mode: str) -> None:
        self.mode = mode
        self.mode_changes.append(mode)
        self.mapper.reset()
        self._recentre_tilt = True  # tilt starts from the pose held once the pointer unfreezes
        url = getattr(self.stream, "url", None)
        page = f" (the 3-D view: {url})" if mode == "3d" and url else ""
        self.log(f"mode {mode}{page}")
        if self.stream is not None:
            self.stream.publish_mode(mode)

    def next_mode(self) -> None:
        i = self.modes.index(self.mode) if self.mode in self.modes else -1
        self.set_mode(self.modes[(i + 1) % len(self.modes)])

    def recentre(self) -> None:
        if self.motion.quat is not None:
            self.tilt.recentre(self.motion.quat)
        if self.stream is not None:
            self.stream.recentre()
        if self.mode == "pointer":
            size = self.backend.screen_size()
            if size:
                self.backend.move_to(size[0] // 2, size[1] // 2)
        self.log("recentred")

    def toggle_pause(self) -> None:
        self.paused = not self.paused
        self.mapper.reset()
        self.log("paused" if self.paused else "resumed")

    def do(self, action: Action) -> None:
        ux, uy = action.undo
        if (ux or uy) and self.mode != "3d":
            self.backend.move(ux, uy)
            self.mapper.reset()  # the smoothing forgets the motion just undone (a knock's jolt)
        k = action.kind
        if self.mode == "3d" and k in ("left_click", "right_click", "middle_click", "double_click",
                                        "double_click_full", "second_click"):
            if self.stream is not None:
                self.stream.publish_event(action.event, action.t_us)
            return
        if k in BUTTONS:
            self.backend.click(BUTTONS[k])
            self.clicks += 1
        elif k in ("double_click", "double_click_full"):
            self.backend.click("left", 2)
            self.clicks += 2
        elif k == "second_click":
            self.backend.click("left")
            self.clicks += 1
        elif k == "next_mode":
            self.next_mode()
        elif k == "recentre":
            self.recentre()
        elif k == "pause":
            self.toggle_pause()
        if self.stream is not None:
            self.stream.publish_event(action.event, action.t_us)

    # -- packets --
    def _move(self, t_us, dx: int, dy: int) -> None:
        self.backend.move(dx, dy)
        if self.move_log is not None:
            self.move_log.moved(self.source.arrival_ns)
        self.moves += 1
        self.actions.moved(t_us, dx, dy)

    def _tilt_step(self, t_us, dt: float) -> None:
        self.motion.update_orientation()  # tilt is the orientation itself: this sample's, not the last
        q = self.motion.quat
        if q is None:
            return
        if self._recentre_tilt:
            self.tilt.recentre(q)
            self._recentre_tilt = False
        dx, dy = self.tilt.update(q, dt)
        if dx or dy:
            self._move(t_us, dx, dy)

    def handle(self, dp) -> None:
        p = dp.packet
        t = dp.t_us
        typ = p.TYPE
        if typ == RawSample.TYPE:
            self._raw_sample(p, t)  # the pointer move first: what the hand feels
            motion = self.motion
            motion.update_orientation()  # the host filter's update, left until the move was out
            if self.stream is not None and motion.uses_host_filter and getattr(self.stream, "wants_pose", True):
                self._publish_pose(t)
            if self._publish_motion is not None:
                self._publish_motion(motion.gyro_dps, motion.accel_g, t, motion.quat)
            motion.run_deferred()  # the filter's bias step and the still-detection's trend sums
        elif typ == Orientation.TYPE:
            dt = self.motion.orientation(p, t)
            if self.motion.uses_host_filter:
                return
            if self.stream is not None and getattr(self.stream, "wants_pose", True):
                self.stream.publish_orientation(self.pose.at(self.motion.quat, t), t)
            if self._publish_motion is not None and not self.motion.raw_seen:
                self._publish_motion(self.motion.gyro_dps, None, t, self.motion.quat)  # rate from successive orientations
            if not self.paused and not self.actions.frozen(t):
                if self.mode == "tilt":
                    self._tilt_step(t, dt)
                elif self.mode == "pointer" and not self.motion.raw_seen:
                    # orientation-only stream: the rate comes from successive orientations
                    dx, dy = self.mapper.update(self.motion.pointer_dps, dt, self.motion.up)
                    if dx or dy:
                        self._move(t, dx, dy)
        elif typ == Event.TYPE:
            for a in self.actions.on_event(p.event_name, t):
                self.do(a)
        elif typ == Status.TYPE:
            self.battery_mv = p.battery_mv
        elif typ == Hello.TYPE:
            self.hello = p
            self.sensor_flags = None  # a new start: its first samples may not have every sensor yet
            self.motion.reset_time()

    def _raw_sample(self, p, t) -> None:
        flags = p.flags
        if flags & _SENSORS_OK != self.sensor_flags:
            self._sensors_changed(flags & _SENSORS_OK)
        dt = self.motion.raw(p, t)
        self.now_us = t
        if self.actions._pending is not None:
            for a in self.actions.due(t):
                self.do(a)
        if self.paused or self.actions.frozen(t) or flags & (RAW_TAP_ACTIVE | RAW_GYRO_STALE) or not flags & RAW_GYRO_OK:
            return  # without the gyroscope nothing says how the sphere turns: the pointer holds still
        if self.mode == "pointer":
            if self.motion.rest_hold.holding:  # lying still (sphere.daemon.gyro_bias.RestHold)
                self.mapper.hold()
                return
            dx, dy = self.mapper.update(self.motion.pointer_dps, dt, self.motion.up)
            if dx or dy:
                self._move(t, dx, dy)
        elif self.mode == "tilt" and self.motion.uses_host_filter:
            self._tilt_step(t, dt)

    def _publish_pose(self, t_us) -> None:
        """The filtered pose to the stream and every output; with a camera, the ball's position too (metres, the
        camera's frame), fused with this sample's orientation and acceleration; None while it is unknown."""
        if self.camera is None:
            self.stream.publish_orientation(self.pose.at(self.motion.quat, t_us), t_us)
            return
        position = None
        if self.motion.quat is not None and self.motion.accel_g is not None:
            position = self.camera.update(self.motion.quat, [v * G_M_S2 for v in self.motion.accel_g], t_us,
                                          [math.radians(v) for v in self.motion.gyro_dps])
        if position is None:
            q = self.pose.at(self.motion.quat, t_us)
        else:
            q, position = self.pose.at(self.motion.quat, t_us, position)
        self.stream.position = None if position is None else [float(v) for v in position]
        self.stream.camera = self.camera.diagnostics()
        watching = bool(getattr(self.stream, "frames_wanted", False))
        if watching != self._ar_watching:
            self._ar_watching = watching
            self.camera.watch_frames(watching)
        if watching:
            frame = self.camera.ar_frame()
            if frame is not None:
                self.stream.publish_frame(frame)
        self.stream.publish_orientation(q, t_us)

    def _sensors_changed(self, bits: int) -> None:
        """A sensor stopped or started answering (RAW_SAMPLE flags): said in the log and on the status line.
        The first samples after a HELLO may lack a sensor that is there (``mag_ok`` waits for the magnetometer's
        first conversion, spec §4.2): that is no fault; one the HELLO says was not found at start is reported."""
        before = self.sensor_flags
        self.sensor_flags = bits
        self.sensors_missing = tuple(name for name, bit in SENSOR_FLAGS if not bits & bit)
        found = self.hello.sensors_found if self.hello is not None else _SENSORS_OK
        for name, bit in SENSOR_FLAGS:
            extra = ": the pointer holds still until it answers again" if bit == RAW_GYRO_OK else ""
            if bits & bit:
                if self._sensors_reported & bit:
                    self._sensors_reported &= ~bit
                    self.log(f"the sphere's {name} answers again")
            elif self._sensors_reported & bit:
                continue
            elif before is not None and before & bit:
                self._sensors_reported |= bit
                self.warn(f"the sphere reports its {name} not answering (RAW_SAMPLE flags){extra}")
            elif before is None and not found & bit:
                self._sensors_reported |= bit
                self.warn(f"the sphere found no {name} at start (HELLO){extra}")

    # -- requests (from signal handlers: they only call request(), the loop acts) --
    def request(self, what: str) -> None:
        """Ask the loop to ``recentre``, ``pause`` (toggle) or ``stop`` at its next turn: safe from a signal
        handler (nothing but a list append; no backend, X or serial call happens in the handler)."""
        if what == "stop":
            self._stopped = True
            self.source._stop = True  # a flag the source's loop checks
        self._requests.append(what)

    def _serve_requests(self) -> None:
        while self._requests:
            what = self._requests.pop(0)
            if what == "recentre":
                self.recentre()
            elif what == "pause":
                self.toggle_pause()
            elif what == "demoted":
                self.warn(self.priority.runaway_message())

    # -- loop --
    def run(self) -> int:
        source = self.source
        collector = self.collector
        priority = self.priority
        if getattr(source, "DEVICE_PACED", False):  # a replay as fast as possible computes without a pause: never in real time
            priority.raise_()
            logger.debug(priority.refused or f"scheduling priority: {priority.granted} for the port -> pointer loop")
        else:
            priority.granted = "not asked (the source is not paced by a device)"
        collector.start()
        try:
            for batch in source:
                if source.generation != self._generation:
                    self._generation = source.generation
                    self.motion.reset_time()
                    self.mapper.reset()
                for dp in batch:
                    self.handle(dp)
                connected = getattr(source, "connected", True)
                if self._connected and not connected and self.stream is not None:
                    self.stream.publish_link_lost()
                self._connected = connected
                if self._requests:
                    self._serve_requests()
                if self.status is not None:
                    self.status.tick(self)
                if self._stopped:
                    break
                collector.step()
                if self.move_log is not None:
                    self.move_log.step()
        finally:
            collector.stop()
            if self.move_log is not None:
                self.move_log.close()
            priority.restore()
            if self.status is not None:
                self.status.tick(self, force=True)
                if self.status.overwrite:
                    try:
                        self.status.stream.write("\n")
                    except (OSError, ValueError):
                        pass
        return 0

    def stop(self) -> None:
        """Stop the loop (from another thread); the source closes its device when its loop sees it."""
        self._stopped = True
        close = getattr(self.source, "close", None)
        if close:
            close()
