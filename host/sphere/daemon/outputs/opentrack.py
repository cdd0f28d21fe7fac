"""OpenTrack's "UDP over network" input: each datagram is six little-endian IEEE-754 doubles,
x, y, z in centimetres then yaw, pitch, roll in degrees (opentrack's input "UDP over network", port 4242
by default). So the sphere drives anything OpenTrack drives (games and simulators through its outputs).

The angles are relative to the reference pose (start or recentre; see :func:`relative_euler_deg`): yaw > 0
turned left, pitch > 0 nose up, roll > 0 rolled right; OpenTrack's per-axis "invert" options flip them to
taste. The position, when a pose source gives one, is the displacement from the reference position in
the reference pose's frame: x right, y up, z forward (towards the screen); 0 otherwise.
"""

from __future__ import annotations

import socket
import struct

from sphere.daemon.outputs.base import Output, OutputUnavailable
from sphere.settings import Param, positive

DATAGRAM = struct.Struct("<6d")


def datagram(angles_deg, moved_m) -> bytes:
    """One OpenTrack datagram: x, y, z (cm: right, up, forward), yaw, pitch, roll (degrees)."""
    x = y = z = 0.0
    if moved_m is not None:
        fwd, left, up = moved_m
        x, y, z = -left * 100.0, up * 100.0, fwd * 100.0
    yaw, pitch, roll = angles_deg
    return DATAGRAM.pack(x, y, z, yaw, pitch, roll)


class OpenTrackOutput(Output):
    NAME = "opentrack"
    PARAMS = {
        "enabled": Param(False, doc="send the pose to OpenTrack's \"UDP over network\" input"),
        "host": Param("127.0.0.1", doc="where OpenTrack runs"),
        "port": Param(4242, doc="OpenTrack's UDP port (its default 4242)", lo=1, hi=65535),
        "rate_hz": Param(100.0, doc="datagrams a second at most", check=positive),
    }

    def __init__(self, host: str = "127.0.0.1", port: int = 4242, rate_hz: float = 100.0, **kw):
        super().__init__(rate_hz, **kw)
        self.address = (host, port)
        try:
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.sock.connect(self.address)  # resolves the host once; errors now, not per datagram
        except OSError as e:
            raise OutputUnavailable(f"cannot send UDP to {host}:{port}: {e}; check [outputs.opentrack] host") from None

    @classmethod
    def from_settings(cls, s, log=None) -> "OpenTrackOutput":
        return cls(s.host, s.port, s.rate_hz)

    def describe(self) -> str:
        return f"UDP to {self.address[0]}:{self.address[1]} (OpenTrack input \"UDP over network\")"

    def send_pose(self, q, angles_deg, moved_m, position_m, t_us) -> None:
        try:
            self.sock.send(datagram(angles_deg, moved_m))
        except ConnectionRefusedError:
            pass  # nobody listening yet (ICMP port unreachable): OpenTrack may start later

    def close(self) -> None:
        self.sock.close()
