"""A 3-D mouse for libspnav programs (Blender, FreeCAD, …): the spacenavd protocol on an AF_UNIX socket.

Programs built on libspnav connect to spacenavd's socket and read 6-DoF events; this output serves the
same protocol, so they take the sphere for a SpaceMouse. The protocol facts below come from the public
sources of spacenavd (``src/proto_unix.c``) and libspnav (``src/proto.h``, ``src/spnav.c``,
``src/util.c``, github.com/FreeSpacenav); the code here is ours.

**Socket.** libspnav connects to ``$SPNAV_SOCKET`` when set, else to the ``socket =`` line of
/etc/spnavrc, else to ``/var/run/spnav.sock`` (``spnav_open``). This server listens on ``[outputs.spacenav]
socket``, else ``$SPNAV_SOCKET``, else ``$XDG_RUNTIME_DIR/spnav.sock`` (the user's own runtime folder,
mode 0600). Blender opens the device only if ``/var/run/spnav.sock`` exists (``access(…, F_OK)`` in
GHOST_NDOFManagerUnix) and then calls ``spnav_open``; host/docs/sphere-mouse.md says how that path comes
to point here. A socket someone answers on is never taken over: a running spacenavd is reported in one
line and this output stays off.

**Protocol v0** (spacenavd before 1.0, and any client that does not ask for more): every event is 8
``int32`` in host order — motion ``0, x, y, z, rx, ry, rz, period_ms``, button ``1`` (press) or ``2``
(release) ``, button`` and zeros. The only thing a v0 client sends is a 4-byte float, its sensitivity,
which multiplies its events' values (spacenavd: ``data[i+1] = (int)(value * sensitivity)``).

**Protocol v1**: libspnav's ``spnav_open`` writes ``REQ_TAG | REQ_CHANGE_PROTO | 1`` = ``0x7faa5501``
first and waits 300 ms for the same word back (the version in its low byte); with no answer it takes the
daemon for v0 and sends a sensitivity of 1.0. After it, requests and replies are ``int32 type; int32
data[7]`` (``struct reqresp``); the reply echoes the type, ``data[6]`` is the status (negative: failure).
Strings (device name, path) come in 24-byte chunks, ``data[6]`` the remaining length, bit 16 set on the
chunks after the first (``spnav_recv_str``). ``REQ_SET_NAME`` (the client's name, the same chunks) is
never answered — libspnav sends it without waiting. Answered: device name, path, axes (6) and buttons
(2) counts, type (unknown), client sensitivity and event mask (default motion | button | device for a
v1 client); anything else at once with a failure status (no USB id, no spacenavd configuration).
``spnav_open``'s requests flush what is pending first and then read the next 32 bytes as the reply, so a
request made while events flow can read an event instead (spacenavd has the same race); the sphere sends
nothing while it lies still, which is when programs ask (at start).

**Motion**: rates, as a puck gives them — steady events (``rate_hz``) while the sphere commands motion and
one all-zero event when it stops (Blender's GHOST_NDOFManagerUnix stops the view when a poll finds no
motion after one that did; FreeCAD redraws per event). Two mappings:

- ``puck``: the sphere's tilt and twist away from the pose it had when 3-D mode started (or at recentre)
  is a deflection: beyond ``dead_zone_deg`` it becomes a rate along the same axis, ``full_scale`` at
  ``full_tilt_deg``, shaped by ``curve`` (1 = linear). Held tilted, the model keeps turning.
- ``direct``: the sphere's own rotation since the last event, in milliradians × ``direct_scale``, about
  the axes of the pose held at the reference (so the view's axes): libspnav's ``spnav_posrot_moveobj``
  turns the object by ``|r| · 0.001`` rad about ``(rx, ry, -rz)`` per event, so with ``direct_scale = 1``
  a model under that helper turns exactly as the sphere turns (a 90° turn gives 90°). Rounding is carried
  to the next event, so nothing is lost. Rates below ``still_dps`` count as still.

Axes (spacenav's, left-handed: x right, y up, z into the screen; rotations as ``spnav_posrot_moveobj``
reads them): turning the sphere left (counter-clockwise seen from above) is ``ry > 0``, nose up (the
part facing the screen rising) ``rx > 0``, rolling right (clockwise seen from behind) ``rz > 0``.
**Zoom** (``zoom = "roll"``, the default): the roll about the axis pointing at the screen is zoom instead
of ``rz`` — clockwise like a screw going in is ``z > 0`` (spacenav's "push the cap into the screen",
zoom in); ``zoom = "none"`` keeps the roll as ``rz`` and sends no translation.

**Buttons**: a single tap is button 0 (press then release), a double tap button 1 (its first knock is a
single tap too, as for the pointer).
"""

from __future__ import annotations

import errno
import math
import os
import selectors
import socket
import stat
import struct
import threading
import time

from sphere import quaternion
from sphere.daemon.outputs.base import Output, OutputUnavailable
from sphere.settings import Param, positive
from sphere.smoothing.pose import log_deg

# -- the protocol (libspnav src/proto.h) --
UEV_MOTION, UEV_PRESS, UEV_RELEASE = 0, 1, 2
REQ_TAG = 0x7FAA0000
REQ_CHANGE_PROTO = 0x5500
REQ_SET_NAME, REQ_SET_SENS, REQ_GET_SENS, REQ_SET_EVMASK, REQ_GET_EVMASK = range(0x1000, 0x1005)
REQ_DEV_NAME, REQ_DEV_PATH, REQ_DEV_NAXES, REQ_DEV_NBUTTONS, REQ_DEV_USBID, REQ_DEV_TYPE = range(0x2000, 0x2006)
EVMASK_MOTION, EVMASK_BUTTON, EVMASK_DEV = 0x01, 0x02, 0x04
REQSTR_CHUNK = 24
REQSTR_CONT_BIT = 0x10000
DEV_UNKNOWN = 0
RECORD = struct.Struct("=8i")  # an event, a request or a reply: 8 int32, host order
WORD = struct.Struct("=i")
FLOAT = struct.Struct("=f")
INT32_MAX = 2**31 - 1

SYSTEM_SOCKET = "/var/run/spnav.sock"  # libspnav's SPNAV_SOCK_PATH
SOCKET_ENV = "SPNAV_SOCKET"
BUTTONS = {"single_tap": 0, "double_tap": 1}
NAXES, NBUTTONS = 6, len(BUTTONS)

#: a client's unsent bytes beyond which its motion events are dropped (a client that does not read); zero
#: events, buttons and replies may go up to HARD_LIMIT, then the client is dropped
SOFT_LIMIT = 64 * RECORD.size
HARD_LIMIT = 256 * RECORD.size
MAX_CLIENTS = 256  # beyond: closed at once (a flood of connections must not take the daemon's descriptors)
GRACE_S = 0.35  # a client that has not asked for a version this long after connecting is a v0 client


def _socket_check(v):
    return None if v == "" or (v.startswith("/") and len(v.encode()) < 108) else \
        "must be an absolute path shorter than 108 bytes (AF_UNIX), or \"\" for $SPNAV_SOCKET / $XDG_RUNTIME_DIR"


#: the ``[outputs.spacenav]`` section
SPACENAV_PARAMS = {
    "enabled": Param(False, doc="a 3-D mouse for libspnav programs (Blender, FreeCAD): spacenavd's protocol"),
    "socket": Param("", doc="the AF_UNIX socket to serve; \"\" = $SPNAV_SOCKET, else $XDG_RUNTIME_DIR/spnav.sock",
        check=_socket_check),
    "protocol": Param(1, doc="highest spacenavd protocol version offered (0 = answer as a spacenavd before 1.0)",
        lo=0, hi=1),
    "mapping": Param("puck", doc="puck: tilt from the start pose is a rate (a SpaceMouse cap); direct: the "
            "sphere's own rotation, the model turns with the hand", choices=("puck", "direct")),
    "zoom": Param("roll", doc="roll: the roll about the axis facing the screen zooms (clockwise = in) instead of "
            "turning; none: roll turns, no zoom", choices=("roll", "none")),
    "only_3d": Param(True, doc="send motion and buttons only in 3-D mode (false: in every mode)"),
    "rate_hz": Param(100.0, doc="motion events a second while the sphere moves", lo=20.0, hi=250.0),
    "name": Param("MARG sphere", doc="the device name clients read (spnav_dev_name)"),
    "dead_zone_deg": Param(3.0, doc="puck: tilt from the start pose that sends nothing", lo=0.0, hi=45.0),
    "full_tilt_deg": Param(30.0, doc="puck: tilt that sends full_scale", lo=1.0, hi=90.0),
    "curve": Param(1.5, doc="puck: rate = full_scale · (tilt beyond the dead zone / the rest)^curve", lo=0.5, hi=4.0),
    "full_scale": Param(350, doc="puck: the value sent at full tilt", lo=1, hi=100000),
    "direct_scale": Param(1.0, doc="direct: units per milliradian turned (1 = a model under "
            "spnav_posrot_moveobj turns as the sphere)", check=positive),
    "still_dps": Param(3.0, doc="direct: rates below this (°/s) count as still", lo=0.0, hi=90.0),
}


def default_socket_path(env=None) -> str:
    env = os.environ if env is None else env
    if env.get(SOCKET_ENV):
        return env[SOCKET_ENV]
    run = env.get("XDG_RUNTIME_DIR")
    if run:
        return os.path.join(run, "spnav.sock")
    return f"/tmp/spnav-{os.getuid()}.sock"


# ------------------------------------------------------------------ one client's protocol (no I/O)

class SpnavSession:
    """One client's side of the protocol: feed it the bytes it sent, get the bytes to answer; encode events
    for it. ``proto`` is None until the client asked for a version (or, for a v0 client, sent anything)."""

    def __init__(self, device_name: str, device_path: str, max_proto: int = 1):
        self.device_name = device_name.encode()
        self.device_path = device_path.encode()
        self.max_proto = max_proto
        self.proto = None
        self.sensitivity = 1.0
        self.evmask = EVMASK_MOTION | EVMASK_BUTTON
        self.client_name = b""
        self._name_expect = 0
        self._in = bytearray()
        self.garbage = None  # why the client was found not to speak the protocol

    def feed(self, data: bytes) -> bytes:
        self._in += data
        out = bytearray()
        while self.garbage is None:
            if self.proto in (None, 0):
                if len(self._in) < 4:
                    break
                (word,) = WORD.unpack_from(self._in)
                if word == REQ_SET_NAME:  # libspnav sends its name whatever the version (spnav_client_name)
                    if len(self._in) < RECORD.size:
                        break
                    rec = RECORD.unpack_from(self._in)
                    del self._in[:RECORD.size]
                    out += self._request(rec[0], list(rec[1:]))
                    continue
                del self._in[:4]
                out += self._word(word)
            else:
                if len(self._in) < RECORD.size:
                    break
                rec = RECORD.unpack_from(self._in)
                del self._in[:RECORD.size]
                out += self._request(rec[0], list(rec[1:]))
        return bytes(out)

    def _word(self, word: int) -> bytes:
        if self.proto is None and (word & 0xFFFFFF00) == REQ_TAG | REQ_CHANGE_PROTO:
            asked = word & 0xFF
            if self.max_proto < 1:  # a v0 daemon reads this as a sensitivity (a NaN: ignored) and says nothing
                self.proto = 0
                return b""
            self.proto = min(asked, self.max_proto)
            if self.proto >= 1:
                self.evmask = EVMASK_MOTION | EVMASK_BUTTON | EVMASK_DEV  # spacenavd's default for v1
            return WORD.pack(REQ_TAG | REQ_CHANGE_PROTO | self.proto)
        self.proto = 0
        (sens,) = FLOAT.unpack(WORD.pack(word))
        if math.isnan(sens) and self.max_proto < 1:
            return b""  # the v1 handshake a v0 server ignores (it is a NaN)
        if not (math.isfinite(sens) and 0.0 < sens <= 1000.0):
            self.garbage = f"sent {word & 0xFFFFFFFF:#010x}, not a sensitivity"
            return b""
        self.sensitivity = sens
        return b""

    def _reply(self, typ: int, data, status: int) -> bytes:
        data = list(data[:6]) + [0] * (6 - len(data[:6]))
        return RECORD.pack(typ, *data, status)

    def _string(self, typ: int, s: bytes) -> bytes:
        out = bytearray()
        remaining = len(s)
        first = True
        while True:
            chunk = s[len(s) - remaining:][:REQSTR_CHUNK].ljust(REQSTR_CHUNK, b"\0")
            out += struct.pack("=i24si", typ, chunk, remaining | (0 if first else REQSTR_CONT_BIT))
            first = False
            remaining -= REQSTR_CHUNK
            if remaining <= 0:
                return bytes(out)

    def _request(self, typ: int, data: list) -> bytes:
        if typ & 0xFFFF0000 not in (REQ_TAG, 0):  # libspnav tags requests, but not string sends (SET_NAME)
            self.garbage = f"sent {typ & 0xFFFFFFFF:#010x}, not a request"
            return b""
        req = typ & 0xFFFF
        if req == REQ_SET_NAME:  # chunks: no answer (libspnav does not wait for one)
            chunk = struct.pack("=6i", *data[:6])
            remlen = data[6] & 0xFFFF
            if not data[6] & REQSTR_CONT_BIT:
                self.client_name, self._name_expect = b"", remlen
            self.client_name = (self.client_name + chunk[:min(REQSTR_CHUNK, remlen)])[:64]
            return b""
        if req == REQ_SET_SENS:
            (sens,) = FLOAT.unpack(WORD.pack(data[0]))
            if math.isfinite(sens) and 0.0 < sens <= 1000.0:
                self.sensitivity = sens
                return self._reply(typ, data, 0)
            return self._reply(typ, data, -1)
        if req == REQ_GET_SENS:
            return self._reply(typ, [WORD.unpack(FLOAT.pack(self.sensitivity))[0]], 0)
        if req == REQ_SET_EVMASK:
            self.evmask = data[0]
            return self._reply(typ, data, 0)
        if req == REQ_GET_EVMASK:
            return self._reply(typ, [self.evmask], 0)
        if req == REQ_DEV_NAME:
            return self._string(typ, self.device_name)
        if req == REQ_DEV_PATH:
            return self._string(typ, self.device_path)
        if req == REQ_DEV_NAXES:
            return self._reply(typ, [NAXES], 0)
        if req == REQ_DEV_NBUTTONS:
            return self._reply(typ, [NBUTTONS], 0)
        if req == REQ_DEV_TYPE:
            return self._reply(typ, [DEV_UNKNOWN], 0)
        return self._reply(typ, data, -1)  # USB id, spacenavd's configuration, anything unknown: failure

    # -- events for this client --
    def motion(self, values, period_ms: int) -> bytes:
        if not self.evmask & EVMASK_MOTION:
            return b""
        s = self.sensitivity
        v = [max(-INT32_MAX, min(INT32_MAX, int(x * s))) for x in values]
        return RECORD.pack(UEV_MOTION, *v, max(0, min(INT32_MAX, int(period_ms))))

    def button(self, bnum: int, press: bool) -> bytes:
        if not self.evmask & EVMASK_BUTTON:
            return b""
        return RECORD.pack(UEV_PRESS if press else UEV_RELEASE, bnum, 0, 0, 0, 0, 0, 0)


# ------------------------------------------------------------------ motion → events (no I/O)

def _qrot(q, v):
    """``v`` rotated by the unit quaternion ``q`` (w, x, y, z)."""
    w, x, y, z = q
    vx, vy, vz = v
    tx = 2 * (y * vz - z * vy)
    ty = 2 * (z * vx - x * vz)
    tz = 2 * (x * vy - y * vx)
    return (vx + w * tx + y * tz - z * ty, vy + w * ty + z * tx - x * tz, vz + w * tz + x * ty - y * tx)


def spnav_axes(v, zoom: str):
    """A rotation (vector, sensor frame at the reference: x to the screen, y left, z up) as spacenav's
    ``x, y, z, rx, ry, rz`` (x right, y up, z into the screen; rotations as spnav_posrot_moveobj reads them)."""
    vx, vy, vz = v
    if zoom == "roll":
        return (0.0, 0.0, vx, -vy, vz, 0.0)
    return (0.0, 0.0, 0.0, -vy, vz, vx)


class SpnavMotion:
    """The events a client gets for the sphere's motion, at most ``rate_hz`` while it moves and one zero event
    when it stops. Feed :meth:`update` every sample (the orientation, sensor to earth, the bias-corrected
    rate in °/s and the device time); it returns ``(values, period_ms)`` to send, or None."""

    def __init__(self, mapping="puck", zoom="roll", rate_hz=100.0, dead_zone_deg=3.0, full_tilt_deg=30.0, curve=1.5,
                 full_scale=350, direct_scale=1.0, still_dps=3.0):
        self.mapping = mapping
        self.zoom = zoom
        self.period_us = 1e6 / rate_hz
        self.dead = math.radians(dead_zone_deg)
        self.full = max(math.radians(full_tilt_deg), self.dead + 1e-6)
        self.curve = curve
        self.full_scale = full_scale
        self.direct_scale = direct_scale
        self.still_rad = math.radians(still_dps)
        self.ref = None  # the reference pose (sensor to earth)
        self.quat = None
        self.moving = False
        self._acc = [0.0] * 6  # direct: x, y, z, rx, ry, rz turned (mrad) and not sent yet
        self._last_t = None  # device time of the last sample (µs)
        self._last_sent = None  # device time of the last event (µs)

    def recentre(self) -> None:
        self.ref = None

    def update(self, q, gyro_dps, t_us):
        self.hold(q, t_us)
        if self.mapping == "puck":
            return self._puck(t_us)
        return self._direct(gyro_dps, t_us)

    def _puck(self, t_us):
        self._last_t = t_us
        q = self.quat
        d = log_deg(quaternion.mul(quaternion.conj(self.ref), q))  # the turn from the centre, reference frame
        v = (math.radians(d[0]), math.radians(d[1]), math.radians(d[2]))
        angle = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        if angle <= self.dead:
            return self._stop(t_us)
        level = self.full_scale * min(1.0, (angle - self.dead) / (self.full - self.dead)) ** self.curve
        k = level / angle
        return self._emit(t_us, spnav_axes((v[0] * k, v[1] * k, v[2] * k), self.zoom))

    def _direct(self, gyro_dps, t_us):
        last, self._last_t = self._last_t, t_us
        if last is None or t_us is None:
            return None
        dt = (t_us - last) * 1e-6
        if not 0.0 < dt < 0.5:
            return None
        d2r = math.pi / 180.0
        w = (gyro_dps[0] * d2r, gyro_dps[1] * d2r, gyro_dps[2] * d2r)
        if w[0] * w[0] + w[1] * w[1] + w[2] * w[2] < self.still_rad * self.still_rad:
            return self._stop(t_us)
        ref = self.ref
        rel = quaternion.mul(quaternion.conj(ref), self.quat)  # body → reference frame
        k = dt * 1000.0 * self.direct_scale  # rad/s → mrad turned in this sample
        wr = _qrot(rel, (w[0] * k, w[1] * k, w[2] * k))
        acc = self._acc
        for i, v in enumerate(spnav_axes(wr, self.zoom)):
            acc[i] += v
        if self.moving and self._last_sent is not None and t_us - self._last_sent < self.period_us - 500:
            return None
        sent = [round(v) for v in acc]
        for i, v in enumerate(sent):
            acc[i] -= v  # what rounding left goes with the next event
        return self._emit(t_us, sent, paced=False)

    def _emit(self, t_us, values, paced=True):
        if paced and self.moving and self._last_sent is not None and t_us is not None \
                and t_us - self._last_sent < self.period_us - 500:
            return None
        period_ms = 0 if self._last_sent is None or t_us is None else round((t_us - self._last_sent) / 1000)
        self._last_sent = t_us
        self.moving = True
        return ([int(round(v)) for v in values], period_ms)

    def hold(self, q, t_us) -> None:
        """Follow the pose without sending (also when nobody listens, or not in 3-D mode)."""
        self.quat = q if type(q) is tuple else tuple(float(v) for v in q)
        if self.ref is None:
            self.ref = self.quat

    def _stop(self, t_us):
        self._acc = [0.0] * 6
        if not self.moving:
            return None
        self.moving = False
        period_ms = 0 if self._last_sent is None or t_us is None else round((t_us - self._last_sent) / 1000)
        self._last_sent = t_us
        return ([0, 0, 0, 0, 0, 0], period_ms)


# ------------------------------------------------------------------ the server (socket I/O)

def socket_owner(path: str):
    """Who answers on ``path``: "none" (no such file), "stale" (a socket nobody listens on), "live" (a socket
    someone accepts on: spacenavd, or another sphere-mouse) or "file" (not a socket)."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return "none"
    except OSError:
        return "file"
    if stat.S_ISLNK(st.st_mode):
        try:
            st = os.stat(path)
        except OSError:
            return "stale"
    if not stat.S_ISSOCK(st.st_mode):
        return "file"
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.settimeout(0.5)
    try:
        s.connect(path)
        return "live"
    except OSError:
        return "stale"
    finally:
        s.close()


class _Client:
    __slots__ = ("sock", "session", "out", "since", "dropped", "name_said")

    def __init__(self, sock, session, now):
        self.sock = sock
        self.session = session
        self.out = bytearray()
        self.since = now
        self.dropped = 0
        self.name_said = False


class SpnavServer:
    """Listens on ``path``; one thread accepts clients and answers their requests; :meth:`motion` and
    :meth:`button` (from the daemon's loop) queue events for every client and send what the socket takes
    without waiting. A client that stops reading loses motion events beyond a small queue, never blocks."""

    def __init__(self, path: str, device_name: str, max_proto: int = 1, log=None, clock=time.monotonic):
        self.path = path
        self.device_name = device_name
        self.max_proto = max_proto
        self.log = log or (lambda m: None)
        self.clock = clock
        self.lock = threading.Lock()
        self.clients: dict[int, _Client] = {}
        self.accepted = 0
        self.refused = 0
        self.dropped_clients = 0
        owner = socket_owner(path)
        if owner == "live":
            who = "a running spacenavd" if os.path.realpath(path) == os.path.realpath(SYSTEM_SOCKET) else \
                "another program (spacenavd or a second sphere-mouse)"
            raise OutputUnavailable(f"{who} answers on {path}; stop it or set [outputs.spacenav] socket "
                                    "to another path")
        if owner == "file":
            raise OutputUnavailable(f"{path} exists and is not a socket; remove it or set [outputs.spacenav] socket")
        if owner == "stale":
            os.unlink(path)
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            folder = os.path.dirname(path)
            if folder:
                os.makedirs(folder, mode=0o700, exist_ok=True)
            old = os.umask(0o177)
            try:
                self.sock.bind(path)
            finally:
                os.umask(old)
            self.sock.listen(16)
        except OSError as e:
            self.sock.close()
            raise OutputUnavailable(f"cannot listen on {path}: {e.strerror or e}; set [outputs.spacenav] socket "
                                    "to a path in a folder you can write") from None
        self.sock.setblocking(False)
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)
        self.sel = selectors.DefaultSelector()
        self.sel.register(self.sock, selectors.EVENT_READ, "listen")
        self.sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="sphere-mouse-spacenav", daemon=True)
        self._thread.start()

    # -- from the daemon's loop --
    def motion(self, values, period_ms: int) -> None:
        zero = not any(values)
        self._send_all(lambda s: s.motion(values, period_ms), droppable=not zero)

    def button(self, bnum: int) -> None:
        self._send_all(lambda s: s.button(bnum, True) + s.button(bnum, False), droppable=False)

    def _send_all(self, encode, droppable: bool) -> None:
        now = self.clock()
        wake = False
        with self.lock:
            for fd, c in list(self.clients.items()):
                s = c.session
                if s.proto is None and now - c.since < GRACE_S:
                    continue  # still deciding which protocol it speaks: an event now would read as the reply
                data = encode(s)
                if not data:
                    continue
                if droppable and len(c.out) >= SOFT_LIMIT:
                    c.dropped += 1
                    continue
                if len(c.out) + len(data) > HARD_LIMIT:
                    self._close(fd, "does not read its events")
                    continue
                c.out += data
                if not self._flush(fd, c):
                    wake = True
        if wake:
            self._wake()

    def _wake(self) -> None:
        try:
            os.write(self._wake_w, b"x")
        except OSError:
            pass

    def _flush(self, fd, c) -> bool:
        """Send what the socket takes now (lock held). True when nothing is left."""
        while c.out:
            try:
                n = c.sock.send(c.out)
            except (BlockingIOError, InterruptedError):
                return False
            except OSError:
                self._close(fd, None)
                return True
            del c.out[:n]
        return True

    def _close(self, fd, why) -> None:
        c = self.clients.pop(fd, None)
        if c is None:
            return
        try:
            self.sel.unregister(c.sock)
        except (KeyError, ValueError):
            pass
        c.sock.close()
        if why:
            self.dropped_clients += 1
            self.log(f"spacenav: dropped a client that {why}")

    # -- the thread --
    def _run(self) -> None:
        while not self._stop:
            try:
                events = self.sel.select(timeout=1.0)
            except (OSError, ValueError):
                if self._stop:
                    return
                raise
            for key, mask in events:
                if key.data == "listen":
                    self._accept()
                elif key.data == "wake":
                    try:
                        while os.read(self._wake_r, 512):
                            pass
                    except (BlockingIOError, OSError):
                        pass
                else:
                    self._serve(key.fd, mask)
            with self.lock:  # ask for write readiness where something waits
                for fd, c in list(self.clients.items()):
                    want = selectors.EVENT_READ | (selectors.EVENT_WRITE if c.out else 0)
                    try:
                        if self.sel.get_key(c.sock).events != want:
                            self.sel.modify(c.sock, want, fd)
                    except (KeyError, ValueError):
                        pass

    def _accept(self) -> None:
        for _ in range(64):
            try:
                conn, _addr = self.sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as e:
                if e.errno in (errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM):
                    return
                raise
            with self.lock:
                if len(self.clients) >= MAX_CLIENTS:
                    conn.close()
                    self.refused += 1
                    if self.refused == 1:
                        self.log(f"spacenav: more than {MAX_CLIENTS} clients at once; refusing the rest")
                    continue
                conn.setblocking(False)
                session = SpnavSession(self.device_name, self.path, self.max_proto)
                self.clients[conn.fileno()] = _Client(conn, session, self.clock())
                self.sel.register(conn, selectors.EVENT_READ, conn.fileno())
                self.accepted += 1

    def _serve(self, fd, mask) -> None:
        with self.lock:
            c = self.clients.get(fd)
            if c is None:
                return
            if mask & selectors.EVENT_WRITE:
                self._flush(fd, c)
                if fd not in self.clients:
                    return
            if not mask & selectors.EVENT_READ:
                return
            if len(c.out) > SOFT_LIMIT:
                return  # answers pile up unread: read no more requests from it until it reads
            try:
                data = c.sock.recv(4096)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                data = b""
            if not data:
                self._close(fd, None)
                return
            reply = c.session.feed(data)
            if c.session.garbage is not None:
                self._close(fd, f"does not speak the protocol ({c.session.garbage})")
                return
            if c.session.client_name and not c.name_said and len(c.session.client_name) >= c.session._name_expect:
                c.name_said = True
                self.log(f"spacenav: client \"{c.session.client_name.decode(errors='replace')}\" connected "
                         f"(protocol v{c.session.proto})")
            if reply:
                c.out += reply
                self._flush(fd, c)

    def close(self) -> None:
        self._stop = True
        self._wake()
        self._thread.join(timeout=2.0)
        with self.lock:
            for fd in list(self.clients):
                self._close(fd, None)
        self.sel.close()
        self.sock.close()
        for fd in (self._wake_r, self._wake_w):
            os.close(fd)
        try:
            if os.path.exists(self.path) and stat.S_ISSOCK(os.lstat(self.path).st_mode):
                os.unlink(self.path)
        except OSError:
            pass


def system_socket_note(path: str) -> str | None:
    """One line on how libspnav programs reach ``path`` when it is not /var/run/spnav.sock, or None."""
    if os.path.realpath(path) == os.path.realpath(SYSTEM_SOCKET):
        return None
    owner = socket_owner(SYSTEM_SOCKET)
    if owner == "live":
        return (f"spacenav: a running spacenavd owns {SYSTEM_SOCKET}; Blender talks to it, not to the sphere "
                f"(stop spacenavd, or start programs with SPNAV_SOCKET={path})")
    if owner == "none":
        return (f"spacenav: no {SYSTEM_SOCKET}, so Blender will not look for a 3-D mouse; `sphere service install "
                f"--spnav-link` makes it point here (FreeCAD: start it with SPNAV_SOCKET={path})")
    return None


# ------------------------------------------------------------------ the output

class SpacenavOutput(Output):
    NAME = "spacenav"
    PARAMS = SPACENAV_PARAMS
    POSE = False  # the sphere's own orientation and rate each sample (motion()); no smoothed pose needed

    def __init__(self, path: str | None = None, name: str = "MARG sphere", protocol: int = 1, only_3d: bool = True,
                 log=None, **motion):
        super().__init__(0.0)
        self.path = path or default_socket_path()
        self.only_3d = only_3d
        self.active = not only_3d
        self.track = SpnavMotion(**motion)
        self.server = SpnavServer(self.path, name, protocol, log)
        note = system_socket_note(self.path)
        if note and log:
            log(note)
        self.events = 0

    @classmethod
    def from_settings(cls, s, log=None) -> "SpacenavOutput":
        return cls(s.socket or None, s.name, s.protocol, s.only_3d, log,
                   mapping=s.mapping, zoom=s.zoom, rate_hz=s.rate_hz, dead_zone_deg=s.dead_zone_deg,
                   full_tilt_deg=s.full_tilt_deg, curve=s.curve, full_scale=s.full_scale,
                   direct_scale=s.direct_scale, still_dps=s.still_dps)

    def describe(self) -> str:
        m = self.track
        return (f"spacenavd protocol v0/v{self.server.max_proto} on {self.path} ({m.mapping}, "
                f"{'zoom by roll' if m.zoom == 'roll' else 'no zoom'}, {'3-D mode only' if self.only_3d else 'every mode'})")

    def _send(self, ev, always=False) -> None:
        if ev is not None and (self.active or always):
            self.server.motion(*ev)
            self.events += 1

    def _listening(self, t_us) -> bool:
        if self.active and self.server.clients:
            return True
        if self.track.moving:  # the last client left, or 3-D mode ended, while moving: close the motion
            self._send(self.track._stop(t_us), always=True)
        return False

    def motion(self, gyro_dps, accel_g, t_us=None, quat=None) -> None:
        if quat is None:
            return
        if not self._listening(t_us):
            self.track.hold(quat, t_us)  # keep the pose, compute nothing
            self.track._last_t = t_us
            return
        self._send(self.track.update(quat, gyro_dps, t_us))

    def recentre(self) -> None:
        self.track.recentre()

    def send_mode(self, name: str) -> None:
        active = not self.only_3d or name == "3d"
        if active and not self.active:
            self.track.recentre()  # the pose held when 3-D mode starts is the puck's centre
        if not active and self.active and self.track.moving:
            self._send(self.track._stop(self.track._last_t))
        self.active = active

    def send_event(self, name: str, t_us) -> None:
        bnum = BUTTONS.get(name)
        if bnum is not None and self.active:
            self.server.button(bnum)

    def close(self) -> None:
        self.server.close()
