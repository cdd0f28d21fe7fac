"""Commands to the sphere and their replies: the one place that numbers commands, waits for the REPLY
that echoes their ``seq`` (spec §3, §5), retries what is safe to repeat, and turns a port that went
away into one clear error.

    link = DeviceLink(port)                      # port: pyserial Serial (or anything with read/write/in_waiting)
    hello = link.hello()                         # HELLO, asking with GET_HELLO if none comes by itself
    reply = link.command(GetCalibration())       # Reply, or None when none came within the timeout
    for dp in link.pump(0.1): ...                # whatever the sphere sent meanwhile (DecodedPacket)

Every packet received is also handed to ``on_packet`` and every byte to ``on_bytes`` (a capture), so a
caller that keeps a RAW_SAMPLE series does not lose the samples that arrive while it waits for a reply.
"""

from __future__ import annotations

import time

import serial

from sphere.errors import LinkLost
from sphere.protocol import GetHello, Hello, PacketStream, Reply, encode_frame

#: Commands that may be sent again when no REPLY came (the reply may be what was lost): doing them twice
#: leaves the device as doing them once. SAVE_CALIBRATION (an EEPROM write), CALIBRATION_STEP (restarts
#: a step) and REBOOT are not repeated.
IDEMPOTENT = frozenset({
    "GET_HELLO", "SET_STREAM", "SET_TAP", "SET_FREE_FALL", "SET_FILTER", "SET_CALIBRATION", "GET_CALIBRATION",
    "LOAD_CALIBRATION", "RESET_CALIBRATION", "IDENTIFY", "GET_STATUS",
})
DEFAULT_RETRIES = 2


def _port_errors():
    return (OSError, serial.SerialException)


class DeviceLink:
    def __init__(self, port, stream: PacketStream | None = None, on_bytes=None, on_packet=None, name: str = ""):
        self.port = port
        self.stream = stream if stream is not None else PacketStream("device")
        self.on_bytes = on_bytes
        self.on_packet = on_packet
        self.name = name or getattr(port, "port", None) or getattr(port, "name", "") or "the port"
        self.tx_seq = 0
        self.sent = 0
        self.bytes_in = 0
        self._errors = _port_errors()

    @property
    def hello_packet(self) -> Hello | None:
        return self.stream.hello

    def _lost(self, e) -> LinkLost:
        return LinkLost(f"{self.name} went away ({e}); is the sphere still plugged in (or paired)? "
                        "Run the command again once it is back")

    def send(self, packet, delimit_first: bool = False) -> int:
        """Send one command; returns the ``seq`` it went out with (the REPLY echoes it in ``cmd_seq``).
        ``delimit_first``: a 0x00 before it, in the same write (ends whatever garbage the device holds, spec §2)."""
        seq = self.tx_seq
        try:
            self.port.write(b"\x00" * delimit_first + encode_frame(packet, seq))
        except self._errors as e:
            raise self._lost(e) from None
        self.tx_seq = (seq + 1) & 0xFF
        self.sent += 1
        return seq

    def send_delimiter(self) -> None:
        """A lone 0x00 (spec §2: any time): the next frame starts clean."""
        try:
            self.port.write(b"\x00")
        except self._errors as e:
            raise self._lost(e) from None

    def read(self) -> list:
        """One read of what has arrived (waiting at most the port's timeout): the packets it completed."""
        try:
            data = self.port.read(max(1, self.port.in_waiting or 1))
        except self._errors as e:
            raise self._lost(e) from None
        except (TypeError, AttributeError) as e:  # pyserial after the fd was closed under it
            raise self._lost(e) from None
        if not data:
            return []
        self.bytes_in += len(data)
        if self.on_bytes is not None:
            self.on_bytes(data)
        out = self.stream.feed(data)
        if self.on_packet is not None:
            for dp in out:
                self.on_packet(dp)
        return out

    def pump(self, seconds: float) -> list:
        """Read for ``seconds`` (at least once); the packets that arrived."""
        end = time.monotonic() + seconds
        out = []
        while True:
            out += self.read()
            if time.monotonic() >= end:
                return out

    def flush_input(self) -> None:
        """Drop what arrived while nobody was reading (a person reading a prompt)."""
        try:
            self.port.reset_input_buffer()
        except (AttributeError, *self._errors):
            pass

    def command(self, packet, timeout_s: float = 1.0, retries: int | None = None) -> Reply | None:
        """Send ``packet`` and wait up to ``timeout_s`` for its REPLY; on silence send it again ``retries`` times
        (default: twice for :data:`IDEMPOTENT` commands, never for the others). None if no REPLY came."""
        if retries is None:
            retries = DEFAULT_RETRIES if packet.NAME in IDEMPOTENT else 0
        for _ in range(retries + 1):
            seq = self.send(packet)
            end = time.monotonic() + timeout_s
            while time.monotonic() < end:
                for dp in self.read():
                    p = dp.packet
                    if p.TYPE == Reply.TYPE and p.cmd_seq == seq and p.cmd_type == packet.TYPE:
                        return p
        return None

    def hello(self, timeout_s: float = 2.0, ask_after_s: float = 0.5) -> Hello | None:
        """The sphere's HELLO: one that arrives by itself within ``ask_after_s``, else asked for with GET_HELLO
        (again every ``ask_after_s``) until ``timeout_s``. None if none came."""
        start = time.monotonic()
        before = self.stream.hello
        next_ask = start + ask_after_s
        while time.monotonic() - start < timeout_s:
            self.read()
            if self.stream.hello is not None and self.stream.hello is not before:
                return self.stream.hello
            if time.monotonic() >= next_ask:
                next_ask += ask_after_s
                self.send(GetHello())
        return None
