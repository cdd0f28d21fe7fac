"""The 3-D page and its WebSocket (:mod:`sphere.daemon.stream3d`) as an output like the others: on by
default, it serves the orientation, position, events and mode on http://127.0.0.1:8765/ (the page) and
ws://127.0.0.1:8765/ws (JSON messages, host/docs/sphere-mouse.md) to local programs and browsers.

It keeps its own pace (``rate_hz`` messages a second, the latest pose each time), so every pose is handed
on as it comes; a port another program holds makes it unavailable, which leaves the pointer running.
"""

from __future__ import annotations

import errno

from sphere.daemon.outputs.base import Output, OutputUnavailable
from sphere.daemon.stream3d import OrientationStream
from sphere.settings import Param, port_number


class PageOutput(Output):
    NAME = "page"
    PARAMS = {
        "enabled": Param(True, doc="serve orientation on a WebSocket and the 3-D page over HTTP (`--no-stream`: off)"),
        "host": Param("127.0.0.1", doc="address to listen on (keep it local)"),
        "port": Param(8765, doc="TCP port of the WebSocket and the page (http://127.0.0.1:PORT/; `--stream-port`)",
                      check=port_number),
        "rate_hz": Param(60.0, doc="orientation messages per second", lo=1.0, hi=200.0),
        "max_clients": Param(16, doc="most WebSocket and page connections at once; more are refused (503)", lo=1,
                             hi=1000),
    }

    @classmethod
    def from_settings(cls, s, log=None) -> "PageOutput":
        return cls(OrientationStream(s.host, s.port, s.rate_hz, log=log, max_clients=s.max_clients))

    def __init__(self, stream: OrientationStream):
        super().__init__(rate_hz=0.0)  # the stream paces its messages itself
        try:
            stream.start()
        except Exception as e:  # a taken port must not stop the pointer
            raise OutputUnavailable(self._why(stream, e)) from None
        self.stream = stream

    @staticmethod
    def _why(stream: OrientationStream, e: Exception) -> str:
        """What went wrong and which setting to change."""
        cause = e.__cause__
        where = f"cannot listen on {stream.host}:{stream.port}"
        if getattr(cause, "errno", None) == errno.EADDRINUSE:
            return (f"{where}: another program (a second sphere-mouse?) holds the port; set --stream-port PORT "
                    "([outputs.page] port), or --no-stream")
        if isinstance(cause, OSError):  # a name that does not resolve, an address not of this machine
            return f"{where}: {cause.strerror or cause}; set [outputs.page] host to an address of this machine (127.0.0.1)"
        return str(e)

    @property
    def url(self) -> str:
        return self.stream.url

    @property
    def frames_wanted(self) -> bool:
        return self.stream.frames_wanted

    def publish_frame(self, frame) -> None:  # the camera's frames, for the page's AR view
        self.stream.publish_frame(frame)

    @property
    def camera(self):
        return self.stream.camera

    @camera.setter
    def camera(self, value):  # the camera's diagnostics, sent with each message
        self.stream.camera = value

    def describe(self) -> str:
        return f"3-D view on {self.url} (WebSocket {self.url.replace('http:', 'ws:')}ws)"

    def orientation(self, q, t_us=None, position=None) -> None:
        self.stream.position = position
        self.stream.publish_orientation(q, t_us)

    def recentre(self) -> None:
        self.stream.recentre()

    def event(self, name: str, t_us=None) -> None:
        self.stream.publish_event(name, t_us)

    def mode(self, name: str) -> None:
        self.stream.publish_mode(name)

    def close(self) -> None:
        self.stream.stop()
