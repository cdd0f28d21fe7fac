"""The daemon's side: :class:`Outputs` passes every call on to the enabled outputs."""

from __future__ import annotations

from sphere.daemon.outputs import REGISTRY
from sphere.daemon.outputs.base import Output, OutputUnavailable


class Outputs:
    """The orientation stream's interface, fanned out to every output."""

    def __init__(self, outputs, log=None):
        self.outputs = list(outputs)
        self.log = log or (lambda m: None)
        self._rates = self._rate_outputs()
        self._position = None
        self._mode = None
        self._camera = None

    @property
    def url(self):
        """The 3-D page's address, when it is one of the outputs."""
        return next((o.url for o in self.outputs if o.url), None)

    @property
    def mode(self):
        return self._mode

    @mode.setter
    def mode(self, value):  # the daemon sets the starting mode this way
        self._mode = value
        self._each(lambda o: o.mode(value))

    def _rate_outputs(self) -> list:
        self._pose = [o for o in self.outputs if getattr(o, "POSE", True)]
        return [o for o in self.outputs if getattr(type(o), "motion", Output.motion) is not Output.motion]

    @property
    def wants_pose(self) -> bool:
        """Whether any output takes the smoothed pose (one with POSE): else the daemon skips it."""
        return bool(self._pose)

    @property
    def position(self):
        return self._position

    @position.setter
    def position(self, value):  # a pose source (hybrid tracking) sets it
        self._position = value

    @property
    def camera(self):
        return self._camera

    @camera.setter
    def camera(self, value):  # the camera's diagnostics, for the outputs that show them (the 3-D page)
        self._camera = value
        for out in self.outputs:
            out.camera = value

    @property
    def frames_wanted(self) -> bool:
        return any(o.frames_wanted for o in self.outputs)

    def publish_frame(self, frame) -> None:  # the camera's frames, for the page's AR view
        for out in self.outputs:
            if out.frames_wanted:
                out.publish_frame(frame)

    def _each(self, call) -> None:
        for out in list(self.outputs):
            try:
                call(out)
            except Exception as e:  # one program gone must not stop the pointer or the others
                self._drop(out, e)

    def _drop(self, out, e) -> None:
        self.log(f"output {out.NAME} stopped: {e}")
        self.outputs.remove(out)
        self._rates = self._rate_outputs()
        try:
            out.close()
        except Exception:
            pass

    def publish_orientation(self, quat, t_us=None) -> None:
        for out in self._pose:
            try:
                out.orientation(quat, t_us, self._position)
            except Exception as e:  # one program gone must not stop the pointer or the others
                self._drop(out, e)

    def publish_motion(self, gyro_dps, accel_g, t_us=None, quat=None) -> None:
        """Each sample's rates, acceleration and orientation, to the outputs that use them."""
        for out in self._rates:
            try:
                out.motion(gyro_dps, accel_g, t_us, quat)
            except Exception as e:
                self._drop(out, e)

    def publish_event(self, event: str, t_us=None) -> None:
        self._each(lambda o: o.event(event, t_us))

    def publish_mode(self, mode: str) -> None:
        self._mode = mode
        self._each(lambda o: o.mode(mode))

    def recentre(self) -> None:
        self._each(lambda o: o.recentre())

    def publish_link_lost(self) -> None:
        """The sphere's link is gone (unplugged, out of range): each output lets go of what it holds."""
        self._each(lambda o: o.link_lost())

    def stop(self) -> None:
        self._each(lambda o: o.close())
        self.outputs = []
        self._rates = []
        self._pose = []


def open_outputs(cfg, log=None) -> list:
    """The outputs enabled in ``cfg`` (``[outputs.NAME] enabled = true``), built from their settings and
    started. One that cannot start is reported and left out: it must not stop the pointer."""
    log = log or (lambda m: None)
    out = []
    for name in REGISTRY:
        settings = cfg.get(REGISTRY.section(name))
        if settings is None or not settings.enabled:
            continue
        try:
            o = REGISTRY.build(name, settings, log=log)
        except OutputUnavailable as e:
            log(f"output {name} cannot start: {e}")
            continue
        log(f"output {name}: {o.describe()}")
        out.append(o)
    return out


def attach(cfg, log=None):
    """What the daemon publishes to: :class:`Outputs` over the enabled outputs, or None when none is."""
    outputs = open_outputs(cfg, log)
    return Outputs(outputs, log) if outputs else None
