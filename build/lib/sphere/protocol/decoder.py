"""A streaming frame decoder: bytes in any chunking → typed packets, with counters (spec §2.1, §3)."""

from __future__ import annotations

from collections import deque
from dataclasses import asdict, dataclass

from cobs import cobs

from sphere.protocol.framing import MAX_ENCODED, MIN_PAYLOAD, crc16
from sphere.protocol.packets import BY_TYPE, Hello, Packet, body_sizes


#: A CRC-good frame whose seq and CRC equal one of the last this many frames' is a duplicate (a link or a
#: receiver that re-sent it): dropped before anyone acts on it, counted in ``duplicates``, not as a gap.
DUPLICATE_WINDOW = 16


@dataclass
class DecoderStats:
    """What the decoder saw. Names follow protocol/spec.md §2.1 and §3."""

    bytes_in: int = 0
    frames_ok: int = 0
    oversize: int = 0
    framing_errors: int = 0
    crc_errors: int = 0
    unknown_types: int = 0
    bad_lengths: int = 0
    bytes_skipped: int = 0
    seq_gaps: int = 0
    frames_lost: int = 0
    restarts: int = 0
    duplicates: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)

    @property
    def errors(self) -> int:
        return self.oversize + self.framing_errors + self.crc_errors + self.unknown_types + self.bad_lengths


class FrameDecoder:
    """Decode one direction of the link.

    ``direction="device"`` (the default) decodes what the device sends; ``"host"`` decodes commands.
    ``feed`` takes any number of bytes and returns the packets completed by them, in order; the result
    does not depend on how the stream is cut into calls.
    """

    def __init__(self, direction: str = "device"):
        if direction not in ("device", "host"):
            raise ValueError("direction is 'device' or 'host'")
        self.direction = direction
        self.stats = DecoderStats()
        self._types = {
            t: (cls, frozenset(body_sizes(cls))) for t, cls in BY_TYPE.items() if cls.DIRECTION == direction
        }
        self._buf = bytearray()
        self._discarding = False  # inside an oversize chunk: drop bytes up to the next delimiter
        self._last_seq: int | None = None
        self._recent: deque = deque()  # (seq << 16 | crc) of the last DUPLICATE_WINDOW frames, oldest first
        self._recent_set: set = set()  # the same, for the lookup

    def restart(self) -> None:
        """A new link: a frame cut off by the old one is dropped without being counted, and the
        sequence count starts again (the frames missed while unplugged were never in transit)."""
        self._buf.clear()
        self._discarding = False
        self._last_seq = None
        self._recent.clear()
        self._recent_set.clear()

    def feed(self, data: bytes) -> list[Packet]:
        stats = self.stats
        stats.bytes_in += len(data)
        buf = self._buf
        if len(data) == 1 and data[0] and not self._discarding and len(buf) < MAX_ENCODED:
            buf += data  # the common case when a port is read byte by byte: a byte inside a frame
            return []
        out: list[Packet] = []
        start = 0
        n = len(data)
        while start < n:
            end = data.find(0, start)
            if end < 0:
                tail = data[start:]
                if self._discarding:
                    stats.bytes_skipped += len(tail)
                else:
                    buf += tail
                    if len(buf) > MAX_ENCODED:
                        stats.oversize += 1
                        stats.bytes_skipped += len(buf)
                        buf.clear()
                        self._discarding = True
                break
            if self._discarding:
                stats.bytes_skipped += end - start + 1
                self._discarding = False
            elif buf:
                buf += data[start:end]
                self._chunk(bytes(buf), out)
                buf.clear()
            elif end > start:
                self._chunk(data[start:end], out)
            start = end + 1
        return out

    def _reject(self, chunk_len: int) -> None:
        self.stats.bytes_skipped += chunk_len + 1

    def _chunk(self, chunk: bytes, out: list[Packet]) -> None:
        stats = self.stats
        if len(chunk) > MAX_ENCODED:
            stats.oversize += 1
            self._reject(len(chunk))
            return
        try:
            payload = cobs.decode(chunk)
        except cobs.DecodeError:
            stats.framing_errors += 1
            self._reject(len(chunk))
            return
        if len(payload) < MIN_PAYLOAD:
            stats.framing_errors += 1
            self._reject(len(chunk))
            return
        crc = payload[-2] | payload[-1] << 8
        if crc16(payload[:-2]) != crc:
            stats.crc_errors += 1
            self._reject(len(chunk))
            return
        type_, seq = payload[0], payload[1]
        entry = self._types.get(type_)
        body = payload[2:-2]
        if entry is not None and entry[0] is Hello and seq == 0 and len(body) in entry[1]:
            if self._last_seq is not None:
                stats.restarts += 1
            self._last_seq = None
            self._recent.clear()
            self._recent_set.clear()
        key = seq << 16 | crc
        recent = self._recent_set
        if key in recent:
            stats.duplicates += 1
            return
        recent.add(key)
        self._recent.append(key)
        if len(self._recent) > DUPLICATE_WINDOW:
            recent.discard(self._recent.popleft())
        self._count_seq(seq)
        if entry is None:
            stats.unknown_types += 1
            self._reject(len(chunk))
            return
        cls, sizes = entry
        if len(body) not in sizes:
            stats.bad_lengths += 1
            self._reject(len(chunk))
            return
        stats.frames_ok += 1
        out.append(cls.unpack_body(body, seq))

    def account(self, packet: Packet) -> None:
        """Count a good frame decoded by another decoder of the same link (a discovery probe's HELLO and
        what followed it), so the counters and the sequence check go on from it."""
        self.stats.frames_ok += 1
        self._count_seq(packet.seq)

    def _count_seq(self, seq: int) -> None:
        last = self._last_seq
        if last is not None:
            gap = (seq - last - 1) & 0xFF
            if gap:
                self.stats.seq_gaps += 1
                self.stats.frames_lost += gap
        self._last_seq = seq


def decode_all(data: bytes, direction: str = "device") -> tuple[list[Packet], DecoderStats]:
    """Decode a whole byte string at once (a capture file's contents, a test vector)."""
    decoder = FrameDecoder(direction)
    packets = decoder.feed(data)
    return packets, decoder.stats
