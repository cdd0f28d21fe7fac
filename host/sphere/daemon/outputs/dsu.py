"""A DSU ("cemuhook") motion server: emulators that aim with a controller's gyro (Dolphin, Cemu, the
Citra/yuzu family) read the sphere as a motion controller over UDP.

The protocol facts come from the public description of cemuhook's protocol, version 1001
(github.com/v1993/cemuhook-protocol), and from clients that read it (Dolphin's DualShockUDPClient, the
DSU servers joycond-cemuhook and PadForge); the code is ours.

- UDP, the server on 127.0.0.1:26760 by default. Every message: ``DSUS`` (server) or ``DSUC`` (client), the
  protocol version (u16, 1001), the length after the 16-byte header (u16; a message shorter than it says
  is dropped, a longer one truncated), a CRC-32 (zlib's) of the message with its own field zeroed, the
  sender's id (u32, random per run), then the message type (u32). Little-endian throughout.
- Types: ``0x100000`` protocol version (answered: u16 1001); ``0x100001`` controller information (the
  request: i32 count ≤ 4, then that many slot bytes < 4; one 32-byte answer per slot: the shared 11-byte
  beginning — slot, state 0/2, model 2 "full gyro", connection type, MAC, battery — and a zero byte);
  ``0x100002`` pad data (the request: flags — 0 all pads, 1 by slot, 2 by MAC — slot, MAC; no answer
  at once: the server streams 100-byte pad data packets to the requester until it stops asking —
  ``timeout_s`` after its last request).
- Pad data after the shared beginning: connected (1), a packet number per client (u32), two button
  bitmasks (the second: Y, B, A, X, R1, L1, R2, L2 from bit 7 down), HOME, touch button, four sticks (128 =
  centre), twelve analog buttons, two touches (6 bytes each), a motion timestamp (u64, µs), accelerometer
  x, y, z (float, g) and gyroscope pitch, yaw, roll (float, °/s).

Axes: the pad is held in front of you (SDL's game-controller frame: x right, y up, z towards you) and the
sphere is held as at the reference, x towards the screen, y left, z up. As DSU servers map SDL's sensors
(PadForge's wiki "DSU Protocol Implementation": accel = −(SDL's accel), pitch = −gx, yaw = +gy,
roll = −gz) this gives: accelerometer in g, (0, −1, 0) lying still (x ← sphere y, y ← −sphere z,
z ← sphere x); gyroscope pitch > 0 nose (the side facing the screen) going down, yaw > 0 turning left
(counter-clockwise seen from above), roll > 0 right side going down (pitch ← sphere ωy, yaw ← ωz,
roll ← ωx). Emulators bind each direction on its own (Dolphin: "Gyro Pitch Up", "Gyro Yaw Left" …), so
a direction that feels reversed is swapped there.

Buttons: a single tap presses A, a double tap B (each held ``tap_hold_ms``, so a client polling at its
own rate sees it). The motion timestamp is the sphere's own clock (µs since its start); data go out at
most ``rate_hz`` a second (the sphere's 200 Hz). Datagrams that are not the protocol are counted and
ignored.
"""

from __future__ import annotations

import errno
import random
import socket
import struct
import threading
import time
import zlib

from sphere.daemon.outputs.base import Output, OutputUnavailable
from sphere.errors import SphereError
from sphere.settings import Param, positive

MAGIC_SERVER, MAGIC_CLIENT = b"DSUS", b"DSUC"
VERSION = 1001
MSG_VERSION, MSG_PORTS, MSG_PAD_DATA = 0x100000, 0x100001, 0x100002
HEADER = struct.Struct("<4sHHII")  # magic, version, length after the header, CRC-32, sender id
TYPE = struct.Struct("<I")
SHARED = struct.Struct("<BBBB6sB")  # slot, state, model, connection, MAC, battery
#: after the shared beginning: connected, packet number, buttons 1, buttons 2, HOME, touch button, sticks
#: LX LY RX RY, 12 analog buttons, two touches, motion timestamp (µs), accel x y z (g), gyro p y r (°/s)
PAD_REST = struct.Struct("<BIBBBB4B12s6s6sQ3f3f")
STATE_CONNECTED, MODEL_FULL_GYRO, CONNECTION_NA = 2, 2, 0
BUTTON_A, BUTTON_B = 0x20, 0x40  # the second bitmask: Y B A X R1 L1 R2 L2 from bit 7
ANALOG_B, ANALOG_A = 1, 2  # in the 12 analog bytes: dpad L D R U, Y, B, A, X, R1, L1, R2, L2
TAPS = {"single_tap": BUTTON_A, "double_tap": BUTTON_B}
SLOT = 0
MAC = bytes.fromhex("025350484552")  # locally administered; "SPHER"
MAX_SUBSCRIBERS = 16


def _host_check(v):
    return None if v and " " not in v else "must be a host name or address, such as \"127.0.0.1\""


#: the ``[outputs.dsu]`` section
DSU_PARAMS = {
    "enabled": Param(False, doc="a DSU (\"cemuhook\") motion server for emulators (Dolphin, Cemu, Citra/yuzu)"),
    "host": Param("127.0.0.1", doc="address to serve on (127.0.0.1: this machine only)", check=_host_check),
    "port": Param(26760, doc="UDP port (cemuhook's 26760)", lo=1, hi=65535),
    "only_3d": Param(False, doc="send motion only in 3-D mode (false: in every mode)"),
    "rate_hz": Param(250.0, doc="pad data packets a second at most (the sphere samples at 200 Hz)", lo=10.0, hi=1000.0),
    "timeout_s": Param(5.0, doc="a client that has not asked for pad data this long stops getting them",
        check=positive),
    "tap_hold_ms": Param(100, doc="how long a tap holds its button (A: single tap, B: double tap)", lo=10, hi=2000),
}


class BadDatagram(SphereError, ValueError):
    """Not a DSU client message; the text is the reason (counted by reason)."""


def crc(message: bytes) -> int:
    """CRC-32 of a message with its CRC field (bytes 8..11) taken as zero."""
    return zlib.crc32(message[12:], zlib.crc32(b"\0\0\0\0", zlib.crc32(message[:8]))) & 0xFFFFFFFF


def parse(datagram: bytes) -> tuple[int, bytes]:
    """(message type, payload) of a client message, or BadDatagram."""
    if len(datagram) < HEADER.size + TYPE.size:
        raise BadDatagram("short")
    magic, version, length, sent_crc, _sender = HEADER.unpack_from(datagram)
    if magic != MAGIC_CLIENT:
        raise BadDatagram("magic")
    if version != VERSION:
        raise BadDatagram("version")
    if length < TYPE.size or HEADER.size + length > len(datagram):
        raise BadDatagram("length")
    message = datagram[:HEADER.size + length]  # a longer datagram is truncated to what it says
    if crc(message) != sent_crc:
        raise BadDatagram("crc")
    (mtype,) = TYPE.unpack_from(message, HEADER.size)
    return mtype, message[HEADER.size + TYPE.size:]


def message(mtype: int, payload: bytes, server_id: int) -> bytes:
    body = TYPE.pack(mtype) + payload
    head = HEADER.pack(MAGIC_SERVER, VERSION, len(body), 0, server_id)
    m = bytearray(head + body)
    struct.pack_into("<I", m, 8, zlib.crc32(m) & 0xFFFFFFFF)
    return bytes(m)


def shared(slot: int, connected: bool) -> bytes:
    if not connected:
        return SHARED.pack(slot, 0, 0, 0, b"\0" * 6, 0)
    return SHARED.pack(slot, STATE_CONNECTED, MODEL_FULL_GYRO, CONNECTION_NA, MAC, 0)


def dsu_motion(gyro_dps, accel_g):
    """The sphere's rates (°/s) and acceleration (g), sensor axes, as DSU's accel x, y, z and gyro pitch,
    yaw, roll (see the module's docstring)."""
    gx, gy, gz = gyro_dps
    if accel_g is None:
        accel = (0.0, -1.0, 0.0)
    else:
        ax, ay, az = accel_g
        accel = (ay, -az, ax)
    return accel, (gy, gz, gx)


def pad_payload(number: int, buttons: int, t_us: int, accel, gyro) -> bytes:
    analog = bytearray(12)
    if buttons & BUTTON_A:
        analog[4 + ANALOG_A] = 255
    if buttons & BUTTON_B:
        analog[4 + ANALOG_B] = 255
    return shared(SLOT, True) + PAD_REST.pack(1, number & 0xFFFFFFFF, 0, buttons, 0, 0, 128, 128, 128, 128,
                                              bytes(analog), b"\0" * 6, b"\0" * 6, max(0, int(t_us)),
                                              *accel, *gyro)


class _Subscriber:
    __slots__ = ("last", "number")

    def __init__(self, now):
        self.last = now
        self.number = 0


class DsuServer:
    """Answers version and controller-information requests on its thread; :meth:`pad` (from the daemon's
    loop) sends pad data to every client that asked for it within ``timeout_s``. Never blocks the caller."""

    def __init__(self, host: str = "127.0.0.1", port: int = 26760, timeout_s: float = 5.0, log=None,
                 clock=time.monotonic):
        self.log = log or (lambda m: None)
        self.clock = clock
        self.timeout_s = timeout_s
        self.server_id = random.getrandbits(32)
        self.subscribers: dict[tuple, _Subscriber] = {}
        self.lock = threading.Lock()
        self.received = 0
        self.bad: dict[str, int] = {}
        self.sent = 0
        self.last_motion = None  # when the sphere's last sample came (slot 0 is connected within 1 s of it)
        try:
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.sock.bind((host, port))
        except OSError as e:
            self.sock.close()
            if e.errno == errno.EADDRINUSE:
                why = "another DSU server (DS4Windows, BetterJoy, a second sphere-mouse) holds it; set [outputs.dsu] port"
            else:  # an address not of this machine, a name that does not resolve
                why = f"{e.strerror or e}; set [outputs.dsu] host to an address of this machine (127.0.0.1)"
            raise OutputUnavailable(f"cannot serve UDP on {host}:{port}: {why}") from None
        self.sock.settimeout(0.5)
        self.address = self.sock.getsockname()
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="sphere-mouse-dsu", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop:
            try:
                data, addr = self.sock.recvfrom(2048)
            except socket.timeout:
                continue
            except OSError:
                if self._stop:
                    return
                continue  # ICMP unreachable from a client gone, and the like
            if self._stop:
                return  # close()'s wake-up
            self.received += 1
            try:
                self._handle(data, addr)
            except BadDatagram as e:
                self.bad[str(e)] = self.bad.get(str(e), 0) + 1
            except OSError:
                pass  # an answer that could not go out

    def _handle(self, data: bytes, addr) -> None:
        mtype, payload = parse(data)
        if mtype == MSG_VERSION:
            self.sock.sendto(message(MSG_VERSION, struct.pack("<H", VERSION), self.server_id), addr)
        elif mtype == MSG_PORTS:
            if len(payload) < 4:
                raise BadDatagram("ports")
            (count,) = struct.unpack_from("<i", payload)
            if not 0 <= count <= 4 or len(payload) < 4 + count:
                raise BadDatagram("ports")
            for slot in payload[4:4 + count]:
                if slot >= 4:
                    raise BadDatagram("ports")
                live = self.last_motion is not None and self.clock() - self.last_motion < 1.0
                info = shared(slot, slot == SLOT and live) + b"\0"
                self.sock.sendto(message(MSG_PORTS, info, self.server_id), addr)
        elif mtype == MSG_PAD_DATA:
            if len(payload) < 8:
                raise BadDatagram("pad request")
            flags, slot, mac = payload[0], payload[1], payload[2:8]
            wants = flags == 0 or (flags & 1 and slot == SLOT) or (flags & 2 and mac == MAC)
            if not wants:
                return  # another pad: not ours
            now = self.clock()
            with self.lock:
                sub = self.subscribers.get(addr)
                if sub is None:
                    if len(self.subscribers) >= MAX_SUBSCRIBERS:
                        self._expire(now)
                        if len(self.subscribers) >= MAX_SUBSCRIBERS:
                            raise BadDatagram("too many clients")
                    sub = self.subscribers[addr] = _Subscriber(now)
                    self.log(f"dsu: {addr[0]}:{addr[1]} subscribed to pad data")
                sub.last = now
        else:
            raise BadDatagram("type")

    def _expire(self, now) -> None:
        for addr in [a for a, s in self.subscribers.items() if now - s.last > self.timeout_s]:
            del self.subscribers[addr]
            self.log(f"dsu: {addr[0]}:{addr[1]} stopped asking; no more pad data to it")

    def pad(self, buttons: int, t_us: int, accel, gyro) -> None:
        now = self.clock()
        with self.lock:
            self._expire(now)
            subs = list(self.subscribers.items())
        for addr, sub in subs:
            sub.number += 1
            try:
                self.sock.sendto(message(MSG_PAD_DATA, pad_payload(sub.number, buttons, t_us, accel, gyro),
                                         self.server_id), addr)
                self.sent += 1
            except (BlockingIOError, OSError):
                pass  # a full buffer or a client gone: the next packet will do

    def close(self) -> None:
        self._stop = True
        host, port = self.address
        try:  # wake the reader now, not at its next timeout (up to 0.5 s more for every stop of the daemon)
            self.sock.sendto(b"", ("127.0.0.1" if host == "0.0.0.0" else host, port))
        except OSError:
            pass
        self._thread.join(timeout=2.0)
        self.sock.close()


class DsuOutput(Output):
    NAME = "dsu"
    PARAMS = DSU_PARAMS
    POSE = False  # rates and acceleration only (motion())

    def __init__(self, host: str = "127.0.0.1", port: int = 26760, only_3d: bool = False, rate_hz: float = 250.0,
                 timeout_s: float = 5.0, tap_hold_ms: int = 100, log=None):
        super().__init__(0.0)
        self.server = DsuServer(host, port, timeout_s, log)
        self.only_3d = only_3d
        self.active = not only_3d
        self.period_us = 1e6 / rate_hz
        self.hold_us = tap_hold_ms * 1000
        self._next_us = None
        self._pressed: dict[int, float] = {}  # button bit → device time it is released (µs)
        self._t_us = None

    @classmethod
    def from_settings(cls, s, log=None) -> "DsuOutput":
        return cls(s.host, s.port, s.only_3d, s.rate_hz, s.timeout_s, s.tap_hold_ms, log)

    def describe(self) -> str:
        host, port = self.server.address
        return f"DSU (cemuhook) motion server on {host}:{port} UDP, pad 1 ({'3-D mode only' if self.only_3d else 'every mode'})"

    def motion(self, gyro_dps, accel_g, t_us=None, quat=None) -> None:
        server = self.server
        server.last_motion = server.clock()
        if t_us is None or not server.subscribers or not self.active:
            return
        self._t_us = t_us
        if self._next_us is not None and t_us < self._next_us:
            return
        self._next_us = t_us + self.period_us - 500
        buttons = 0
        for bit, until in list(self._pressed.items()):
            if t_us < until:
                buttons |= bit
            else:
                del self._pressed[bit]
        accel, gyro = dsu_motion(gyro_dps, accel_g)
        server.pad(buttons, t_us, accel, gyro)

    def send_event(self, name: str, t_us) -> None:
        bit = TAPS.get(name)
        if bit is not None and self.active:
            start = t_us if t_us is not None else (self._t_us or 0)
            self._pressed[bit] = start + self.hold_us

    def send_mode(self, name: str) -> None:
        self.active = not self.only_3d or name == "3d"

    def close(self) -> None:
        s = self.server
        s.close()
        bad = sum(s.bad.values())
        reasons = ", ".join(f"{k} {v}" for k, v in sorted(s.bad.items()))
        s.log(f"dsu: {s.received} datagrams received, {bad} ignored{f' ({reasons})' if bad else ''}; "
              f"{s.sent} pad data packets sent")
