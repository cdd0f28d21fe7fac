"""Open Sound Control over UDP (python-osc), for creative tools (Pure Data, Max, TouchDesigner, Processing).

Messages (``prefix`` "/sphere" by default):

======================  ======================================================================
``/sphere/quat``        w x y z — the orientation, sensor to earth (NWU), as the WebSocket sends it
``/sphere/euler``       yaw pitch roll — degrees from the reference pose (yaw > 0 left, pitch > 0
                        nose up, roll > 0 right side down)
``/sphere/position``    x y z — metres, earth frame (NWU), when a pose source gives one
``/sphere/event``       single_tap | double_tap | free_fall
``/sphere/mode``        pointer | tilt | 3d
======================  ======================================================================
"""

from __future__ import annotations

from sphere.daemon.outputs.base import Output, OutputUnavailable
from sphere.settings import Param, positive


def _prefix(v):
    return None if v.startswith("/") and not v.endswith("/") and " " not in v else \
        "must be an OSC address such as \"/sphere\" (starts with /, no trailing /, no spaces)"


class OscOutput(Output):
    NAME = "osc"
    PARAMS = {
        "enabled": Param(False, doc="send OSC messages over UDP"),
        "host": Param("127.0.0.1", doc="where the OSC receiver runs"),
        "port": Param(9000, doc="the receiver's UDP port", lo=1, hi=65535),
        "prefix": Param("/sphere", doc="the messages' address prefix", check=_prefix),
        "rate_hz": Param(60.0, doc="pose messages a second at most", check=positive),
    }

    def __init__(self, host: str = "127.0.0.1", port: int = 9000, prefix: str = "/sphere", rate_hz: float = 60.0,
                 **kw):
        super().__init__(rate_hz, **kw)
        try:
            from pythonosc.udp_client import SimpleUDPClient  # optional: python-osc (the daemon extra)
        except ImportError:
            raise OutputUnavailable("python-osc is not installed: pip install python-osc "
                                    "(or the daemon extra: pip install 'marg-sphere[daemon]')") from None
        try:
            self.client = SimpleUDPClient(host, port)
        except OSError as e:
            raise OutputUnavailable(f"cannot send UDP to {host}:{port}: {e}; check [outputs.osc] host") from None
        self.address = (host, port)
        self.prefix = prefix

    @classmethod
    def from_settings(cls, s, log=None) -> "OscOutput":
        return cls(s.host, s.port, s.prefix, s.rate_hz)

    def describe(self) -> str:
        return f"OSC to {self.address[0]}:{self.address[1]} ({self.prefix}/quat, /euler, /event, /mode)"

    def _send(self, path: str, value) -> None:
        try:
            self.client.send_message(self.prefix + path, value)
        except ConnectionRefusedError:
            pass  # nobody listening yet

    def send_pose(self, q, angles_deg, moved_m, position_m, t_us) -> None:
        self._send("/quat", [float(v) for v in q])
        self._send("/euler", [float(v) for v in angles_deg])
        if position_m is not None:
            self._send("/position", [float(v) for v in position_m])

    def send_event(self, name: str, t_us) -> None:
        self._send("/event", name)

    def send_mode(self, name: str) -> None:
        self._send("/mode", name)
