"""Bytes from one link → packets with their device time: the one place that turns a byte stream into
what the daemon, captures, calibration and the monitor act on.

    stream = PacketStream()
    for dp in stream.feed(chunk):      # DecodedPacket(packet, t_us): t_us unwrapped (None for timeless packets)
        ...
    stream.stats                       # the frame decoder's counters (spec §2.1, §3)
    stream.hello                       # the last HELLO seen
    stream.restart()                   # a new link (a reconnect): nothing of the old one carries over

A HELLO with ``seq`` 0 means the device restarted (spec §3): its clock started again, so the time base
restarts there. A frame received twice is dropped by the decoder before it gets here (``duplicates``).
"""

from __future__ import annotations

from dataclasses import dataclass

from sphere.protocol.decoder import DecoderStats, FrameDecoder
from sphere.protocol.packets import Hello, Packet
from sphere.protocol.timebase import TimeUnwrapper

_HELLO = Hello.TYPE


@dataclass
class DecodedPacket:
    """A packet with the device time unwrapped (``t_us`` is None for packets without a time)."""

    packet: Packet
    t_us: int | None


class PacketStream:
    """Frames → :class:`DecodedPacket` for one direction of one link."""

    def __init__(self, direction: str = "device"):
        self.decoder = FrameDecoder(direction)
        self.unwrap = TimeUnwrapper()
        self.hello: Hello | None = None

    @property
    def stats(self) -> DecoderStats:
        return self.decoder.stats

    def restart(self) -> None:
        """A new connection: a frame cut off by the old link is dropped uncounted, sequence numbers and
        device time start again."""
        self.decoder.restart()
        self.unwrap.reset()

    def packet(self, p: Packet) -> DecodedPacket:
        """One decoded packet (from :meth:`feed`, or a packet decoded elsewhere) with its time unwrapped."""
        if p.TYPE == _HELLO:
            if p.seq == 0:
                self.unwrap.reset()
            self.hello = p
        t = getattr(p, "t_us", None)
        return DecodedPacket(p, self.unwrap(t) if t is not None else None)

    def adopt(self, packets, pending: bytes = b"") -> list[DecodedPacket]:
        """Packets another decoder of this link already decoded (a discovery probe's HELLO onwards), counted
        here as if this stream had decoded them; ``pending``: that decoder's frame not complete yet
        (``FrameDecoder.pending``), which this stream goes on gathering (else its end is a framing error here and
        its frame a sequence gap)."""
        out = []
        for p in packets:
            self.decoder.account(p)
            out.append(self.packet(p))
        if pending:
            self.decoder.feed(pending)  # no delimiter in it: kept, nothing decoded
        return out

    def feed(self, data: bytes) -> list[DecodedPacket]:
        packets = self.decoder.feed(data)
        if not packets:
            return []
        out = []
        unwrap = self.unwrap
        for p in packets:  # :meth:`packet`, inlined: this runs for every frame on the pointer's path
            if p.TYPE == _HELLO:
                if p.seq == 0:
                    unwrap.reset()
                self.hello = p
            t = getattr(p, "t_us", None)
            out.append(DecodedPacket(p, unwrap(t) if t is not None else None))
        return out
