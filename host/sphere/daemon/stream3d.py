"""The 3-D stream: orientation (and events, mode changes) as JSON over a WebSocket on 127.0.0.1, and
the built-in page that shows a 3-D object turning with the sphere.

    http://127.0.0.1:8765/      the page (sphere.daemon.page)
    ws://127.0.0.1:8765/ws      one JSON object per message:
        {"type": "orientation", "t_us": ..., "quat": [w, x, y, z], "frame": "NWU", "mode": "3d", "position": null,
         "camera": null}     with a camera: "position" [x, y, z] m in the camera's frame (null while unknown),
                             "camera" {"frames", "found", "accepted", "gated", "reacquired", "late", "alignment"}:
                             frames seen, with the ball, fixes used, rejected by the gate (an implausible jump
                             against the IMU's prediction), re-acquisitions, too late; the camera-to-earth
                             rotation known
        {"type": "frame", "index": k, "jpeg": "<base64>", "camera": {"width", "height", "fx", "fy", "cx", "cy",
         "dist": [k1, k2, p1, p2, k3]}, "radius_m": 0.04, "position": [x, y, z] | null,
         "rotation": [[...], [...], [...]] | null, "outline": {"centre": [u, v], "radius": r, "verdict": ...} | null}
                             the camera's newest frame with the ball's pose at its exposure (camera frame;
                             rotation body → camera) and the detector's outline, for the page's AR view: only to a
                             client that sent {"subscribe": "frames"}, at most rate_hz a second
        {"type": "event", "event": "single_tap", "t_us": ...}
        {"type": "mode", "mode": "tilt"}
        {"type": "recentre", "quat": [w, x, y, z]}

The server runs its own asyncio loop in a thread; the daemon's calls (``publish_*``) only store the
newest value or queue a message, so they cost the pointer path next to nothing. Orientation goes out
at most ``rate_hz`` times a second, only when it changed.
"""

from __future__ import annotations

import asyncio
import base64
import collections
import http
import json
import logging
import threading
import time

from sphere.daemon.page import PAGE_HTML, static_response


class _QuietLog:
    """What goes wrong with clients (a refused flood, a client that vanished) as one line at most every 10 s,
    never a traceback: a hostile page or a connection flood must not fill the journal."""

    def __init__(self, log, every_s: float = 10.0):
        self.log = log or (lambda m: None)
        self.every_s = every_s
        self._clock = time.monotonic
        self._last = -1e18
        self.suppressed = 0
        self.logger = logging.Logger("sphere.daemon.stream.websockets", logging.WARNING)  # this server's own
        self.logger.addHandler(_Forward(self))

    def __call__(self, msg: str) -> None:
        now = self._clock()
        if now - self._last < self.every_s:
            self.suppressed += 1
            return
        extra = f" ({self.suppressed} more like it not shown)" if self.suppressed else ""
        self._last, self.suppressed = now, 0
        self.log(f"3-D stream: {msg}{extra}")


class _Forward(logging.Handler):
    """Hands a log record's message (never its traceback) to a _QuietLog."""

    def __init__(self, quiet):
        super().__init__()
        self.quiet = quiet

    def emit(self, record):
        self.quiet(record.getMessage())


class OrientationStream:
    def __init__(self, host: str = "127.0.0.1", port: int = 8765, rate_hz: float = 60.0, log=None,
                 max_clients: int = 16):
        self.max_clients = max_clients
        self.refused = 0  # requests refused (foreign Host or Origin, too many connections)
        self.open_connections = 0
        self._quiet = _QuietLog(log)
        self.host = host
        self.port = port
        self.rate_hz = rate_hz
        self.log = log or (lambda m: None)
        self.mode = None
        self.position = None
        self.camera = None  # the camera's diagnostics (sphere.camera.daemon_source.CameraPosition.diagnostics)
        self.clients = set()
        self.frame_clients = set()  # clients that asked for the camera's frames (the page's AR view)
        self._frame = None
        self.sent = 0
        self._quat = None
        self._t_us = None
        self._dirty = False
        self._queue: collections.deque = collections.deque(maxlen=256)
        self._loop = None
        self._thread = None
        self._started = threading.Event()
        self._error: BaseException | None = None
        self._stop_event = None

    @property
    def url(self) -> str:
        """The page's address (the WebSocket is ``ws://…/ws``)."""
        return f"http://{self.host}:{self.port}/"

    # -- daemon side (any thread) --
    def publish_orientation(self, quat, t_us=None) -> None:
        if quat is None:
            return
        self._quat = quat
        self._t_us = t_us
        self._dirty = True

    @property
    def frames_wanted(self) -> bool:
        """A client watches the camera's frames (the daemon then keeps them)."""
        return bool(self.frame_clients)

    def publish_frame(self, frame: dict) -> None:
        """The camera's newest frame (sphere.camera.daemon_source.CameraPosition.ar_frame); coded as JPEG in the
        server's thread, not the daemon's."""
        self._frame = frame

    def publish_event(self, event: str, t_us=None) -> None:
        self._queue.append({"type": "event", "event": event, "t_us": t_us})

    def publish_mode(self, mode: str) -> None:
        self.mode = mode
        self._queue.append({"type": "mode", "mode": mode})

    def publish_link_lost(self) -> None:
        """The sphere's link is gone: the page keeps showing the last pose (nothing to let go of)."""

    def recentre(self) -> None:
        q = self._quat
        self._queue.append({"type": "recentre", "quat": [round(float(v), 6) for v in q] if q is not None else None})

    # -- server --
    def start(self, timeout_s: float = 5.0) -> None:
        self._thread = threading.Thread(target=self._run, name="sphere-mouse-stream", daemon=True)
        self._thread.start()
        if not self._started.wait(timeout_s):
            raise RuntimeError("the stream server did not start")
        if self._error is not None:
            raise RuntimeError(f"cannot listen on {self.host}:{self.port}: {self._error}") from self._error

    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as e:  # report bind errors to start()
            self._error = e
            self._started.set()

    # -- who may connect --
    def _local_names(self) -> set[str]:
        names = {"127.0.0.1", "localhost", "[::1]", "::1"}
        if self.host not in ("", "0.0.0.0", "::"):
            names.add(self.host)
        return names

    def allowed_host(self, host_header: str | None) -> bool:
        """The Host header names this machine as a loopback name (not a DNS name rebound to 127.0.0.1)."""
        if not host_header:
            return False
        host = host_header.strip().lower()
        if host.startswith("["):
            name = host[: host.find("]") + 1]
        else:
            name = host.rsplit(":", 1)[0] if host.count(":") == 1 else host
        return name in self._local_names()

    def allowed_origin(self, origin: str | None) -> bool:
        """No Origin (a program, not a page) or the page this server serves, on a loopback name."""
        if origin is None:
            return True
        origin = origin.strip().lower()
        for scheme in ("http://", "https://"):
            if origin.startswith(scheme):
                return self.allowed_host(origin[len(scheme):])
        return False

    def _refuse(self, connection, status, text: str):
        self.refused += 1
        return connection.respond(status, text)

    def _process_request(self, connection, request):
        if not self.allowed_host(request.headers.get("Host")):
            return self._refuse(connection, http.HTTPStatus.FORBIDDEN,
                                "forbidden: this server answers only on 127.0.0.1 / localhost\n")
        if not self.allowed_origin(request.headers.get("Origin")):
            return self._refuse(connection, http.HTTPStatus.FORBIDDEN,
                                "forbidden: only the page served here (or a local program) may connect\n")
        path = request.path.split("?", 1)[0]
        if path == "/ws":
            return None  # go on with the WebSocket handshake
        if path in ("/", "/index.html"):
            response = connection.respond(http.HTTPStatus.OK, PAGE_HTML)
            del response.headers["Content-Type"]
            response.headers["Content-Type"] = "text/html; charset=utf-8"
            response.headers["Cache-Control"] = "no-store"
            return response
        found = static_response(path)  # three.js, shipped in the package
        if found is not None:
            response = connection.respond(http.HTTPStatus.OK, found[0])
            del response.headers["Content-Type"]
            response.headers["Content-Type"] = found[1]
            return response
        return connection.respond(http.HTTPStatus.NOT_FOUND, "not found: the page is at / and the WebSocket at /ws\n")

    async def _handler(self, ws) -> None:
        self.clients.add(ws)
        try:
            if self.mode is not None:
                await ws.send(json.dumps({"type": "mode", "mode": self.mode}))
            async for text in ws:  # a client may ask for the camera's frames; anything else is ignored
                if _subscription(text) == "frames":
                    self.frame_clients.add(ws)
        except Exception:
            pass
        finally:
            self.clients.discard(ws)
            self.frame_clients.discard(ws)

    async def _main(self) -> None:
        from websockets.asyncio.server import ServerConnection, broadcast, serve  # optional: websockets (the daemon extra)

        self._loop = asyncio.get_running_loop()
        self._loop.set_exception_handler(lambda loop, context: self._quiet(context.get("message", "error")))
        self._stop_event = asyncio.Event()
        stream = self

        class Limited(ServerConnection):
            """Refuses a connection beyond ``max_clients`` before reading from it (an idle flood of connections
            then costs no handshake, and the daemon keeps descriptors for the sphere's port)."""

            def connection_made(self, transport):
                stream.open_connections += 1
                if stream.open_connections > stream.max_clients:
                    stream.refused += 1
                    stream._quiet(f"more than {stream.max_clients} connections at once: refusing")
                    transport.abort()
                    return
                super().connection_made(transport)

            def connection_lost(self, exc):
                stream.open_connections -= 1
                super().connection_lost(exc)

        async with serve(self._handler, self.host, self.port, process_request=self._process_request,
                         compression=None, close_timeout=1.0, open_timeout=3.0, create_connection=Limited,
                         logger=self._quiet.logger) as server:
            self.port = server.sockets[0].getsockname()[1]
            self._started.set()
            period = 1.0 / self.rate_hz
            while not self._stop_event.is_set():
                try:
                    await asyncio.wait_for(self._stop_event.wait(), period)
                except asyncio.TimeoutError:
                    pass
                messages = []
                while self._queue:
                    messages.append(self._queue.popleft())
                if self._dirty and self._quat is not None:
                    self._dirty = False
                    messages.append({"type": "orientation", "t_us": self._t_us,
                                     "quat": [round(float(v), 6) for v in self._quat], "frame": "NWU",
                                     "mode": self.mode, "position": self.position, "camera": self.camera})
                if messages and self.clients:
                    for m in messages:
                        broadcast(self.clients, json.dumps(m))
                        self.sent += 1
                frame, self._frame = self._frame, None
                if frame is not None and self.frame_clients:
                    broadcast(self.frame_clients, json.dumps(_frame_message(frame)))
                    self.sent += 1

    def stop(self) -> None:
        if self._loop is not None and self._stop_event is not None:
            self._loop.call_soon_threadsafe(self._stop_event.set)
        if self._thread is not None:
            self._thread.join(5)


def _subscription(text) -> str | None:
    """What a client's message subscribes to (``{"subscribe": "frames"}``), or None for anything else."""
    if not isinstance(text, str) or len(text) > 200:
        return None
    try:
        msg = json.loads(text)
    except ValueError:
        return None
    return msg.get("subscribe") if isinstance(msg, dict) else None


def _frame_message(frame: dict) -> dict:
    """A frame for the page: its image as base64 JPEG (quality 85) beside the pose and outline."""
    import cv2  # optional: OpenCV (the camera extra); frames come only from a camera

    ok, jpeg = (False, None) if frame.get("image") is None else \
        cv2.imencode(".jpg", frame["image"], [cv2.IMWRITE_JPEG_QUALITY, 85])
    out = {k: v for k, v in frame.items() if k != "image"}
    out["type"] = "frame"
    out["jpeg"] = base64.b64encode(jpeg.tobytes()).decode("ascii") if ok else None
    return out
