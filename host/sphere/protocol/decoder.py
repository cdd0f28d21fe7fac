"""A streaming frame decoder: bytes in any chunking → typed packets, with counters (spec §2.1, §3)."""

from __future__ import annotations

from binascii import crc_hqx
from collections import deque
from collections.abc import Sequence
from dataclasses import asdict, dataclass

from cobs.cobs import DecodeError
from cobs.cobs import decode as cobs_decode

from sphere.protocol.framing import CRC16_INIT, MAX_ENCODED, MAX_PAYLOAD, MIN_PAYLOAD
from sphere.protocol.packets import BY_TYPE, Hello, Packet


#: A CRC-good frame whose seq and CRC equal one of the last this many frames' is a duplicate (a link or a
#: receiver that re-sent it): dropped before anyone acts on it, counted in ``duplicates``, not as a gap.
DUPLICATE_WINDOW = 16


@dataclass(slots=True)
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


#: What :meth:`FrameDecoder.feed` returns for bytes that complete no frame without looking further.
NOTHING: tuple = ()
DELIMITER = b"\x00"


def _types_of(direction: str) -> tuple:
    """For each type byte, ``(class, unpackers)`` of the packet type sent in ``direction`` (None: no such type);
    ``unpackers[n]`` decodes a payload whose body is ``n`` bytes long (None: not a length of that type). Tuples
    indexed by the byte: the hot path's lookups without a method call."""
    types: list = [None] * 256
    for t, cls in BY_TYPE.items():
        if cls.DIRECTION == direction:
            unpackers: list = [None] * (MAX_PAYLOAD - MIN_PAYLOAD + 1)
            for n, unpack in cls.payload_decoders().items():
                unpackers[n] = unpack
            types[t] = (cls, tuple(unpackers))
    return tuple(types)


class FrameDecoder:
    """Decode one direction of the link.

    ``direction="device"`` (the default) decodes what the device sends; ``"host"`` decodes commands.
    ``feed`` takes any number of bytes and returns the packets completed by them, in order; the result
    does not depend on how the stream is cut into calls.
    """

    __slots__ = ("direction", "_stats", "duplicate_window", "_types", "_buf", "_counted", "_room", "_last_seq",
                 "_recent", "_recent_set")

    def __init__(self, direction: str = "device", duplicate_window: int = DUPLICATE_WINDOW):
        if direction not in ("device", "host"):
            raise ValueError("direction is 'device' or 'host'")
        self.direction = direction
        self.duplicate_window = duplicate_window  # 0: every frame is returned, a repeat too (what a soak checks)
        self._stats = DecoderStats()
        # by type byte: (class, by body length: function (payload, seq) -> packet, or None), or None
        self._types = _types_of(direction)
        self._buf = bytearray()
        self._counted = 0  # how many of _buf's bytes ``bytes_in`` counts (not those the byte-at-a-time path added)
        # how long the frame being gathered in _buf may grow before it is oversize; 0 inside an oversize chunk
        # (its bytes are dropped up to the next delimiter)
        self._room = MAX_ENCODED
        self._last_seq: int | None = None
        # (seq << 16 | crc) of the last DUPLICATE_WINDOW frames, oldest first; -1: no frame yet (no key is < 0)
        self._recent: deque = deque((-1,) * duplicate_window)
        self._recent_set: set = set()  # the same, for the lookup

    @property
    def stats(self) -> DecoderStats:
        """The counters, up to the last byte fed. Bytes without a delimiter are only kept when they come (the
        byte-at-a-time path): they are counted here or at the next call that brings a delimiter."""
        self._count_gathered()
        return self._stats

    def _count_gathered(self) -> None:
        buf = self._buf
        n = len(buf)
        self._stats.bytes_in += n - self._counted
        if n > MAX_ENCODED:  # gathered past the longest frame: dropped as feed's loop drops it
            self._stats.oversize += 1
            self._stats.bytes_skipped += n
            buf.clear()
            self._room = 0
            n = 0
        self._counted = n

    def restart(self) -> None:
        """A new link: a frame cut off by the old one is dropped without being counted, and the
        sequence count starts again (the frames missed while unplugged were never in transit)."""
        self._count_gathered()  # the cut frame's bytes were received
        self._buf.clear()
        self._counted = 0
        self._room = MAX_ENCODED
        self._last_seq = None
        self._forget_recent()

    def pending(self) -> bytes:
        """The bytes after the last delimiter: the start of a frame not complete yet (none inside a chunk dropped as
        oversize). Another decoder of the same link that takes over from this one is fed them first."""
        return bytes(self._buf) if self._room else b""

    def _forget_recent(self) -> None:
        self._recent = deque((-1,) * self.duplicate_window)
        self._recent_set.clear()

    def feed(self, data: bytes) -> Sequence[Packet]:
        """The packets the bytes in ``data`` complete, in order: a list, or :data:`NOTHING` (an empty tuple) when
        ``data`` brings no delimiter (a port read a byte at a time gets one per byte: no list is built for it)."""
        buf = self._buf
        if 0 not in data and len(buf) < self._room:
            # no delimiter: only kept (see stats; what is too long is found at the next call). The common case
            # when a port is read byte by byte: a byte inside a frame
            buf += data
            return NOTHING
        stats = self._stats
        stats.bytes_in += len(data) + len(buf) - self._counted
        if buf and data == DELIMITER:  # a frame's last byte, fed alone (buf is never kept while _room is 0)
            chunks = (bytes(buf),)
            buf.clear()
        else:
            # the delimited chunks; the last piece has no delimiter after it yet (b"" when data ends with one)
            chunks = data.split(DELIMITER)
            tail = chunks.pop()
            if chunks:
                if not self._room:  # the end of a chunk already dropped as oversize: its bytes and delimiter
                    stats.bytes_skipped += len(chunks[0]) + 1
                    self._room = MAX_ENCODED
                    chunks[0] = b""
                elif buf:
                    buf += chunks[0]
                    chunks[0] = bytes(buf)
                    buf.clear()
            if tail:
                if not self._room:
                    stats.bytes_skipped += len(tail)
                else:
                    buf += tail
                    if len(buf) > MAX_ENCODED:
                        stats.oversize += 1
                        stats.bytes_skipped += len(buf)
                        buf.clear()
                        self._room = 0
        self._counted = len(buf)
        out: list[Packet] = []
        types = self._types
        for chunk in chunks:
            if not chunk:  # two delimiters in a row: nothing between them to count
                continue
            # one delimited chunk: every check of spec §2.1 in order, the first that fails counted (a rejected
            # chunk's bytes and its delimiter are skipped); the order and the counters are the contract, the
            # shape is the hot path's (written out here, once per frame)
            if len(chunk) > MAX_ENCODED:
                stats.oversize += 1
                stats.bytes_skipped += len(chunk) + 1
                continue
            try:
                payload = cobs_decode(chunk)
            except DecodeError:
                stats.framing_errors += 1
                stats.bytes_skipped += len(chunk) + 1
                continue
            size = len(payload) - 4  # the body's (payload: type, seq, body, CRC)
            if size < 0:
                stats.framing_errors += 1
                stats.bytes_skipped += len(chunk) + 1
                continue
            crc = payload[-2] | payload[-1] << 8
            if crc_hqx(payload[:-2], CRC16_INIT) != crc:
                stats.crc_errors += 1
                stats.bytes_skipped += len(chunk) + 1
                continue
            seq = payload[1]
            entry = types[payload[0]]  # (class, unpackers by body length) or None
            if seq == 0 and entry is not None and entry[0] is Hello and entry[1][size] is not None:
                if self._last_seq is not None:
                    stats.restarts += 1
                self._last_seq = None
                self._forget_recent()
            key = seq << 16 | crc
            recent = self._recent_set
            if key in recent:
                stats.duplicates += 1
                continue
            recent.add(key)
            window = self._recent
            window.append(key)
            recent.discard(window.popleft())  # the window holds DUPLICATE_WINDOW keys (placeholders at first)
            last = self._last_seq  # :meth:`_count_seq`, written out
            if last is not None and (seq - last - 1) & 0xFF:
                stats.seq_gaps += 1
                stats.frames_lost += (seq - last - 1) & 0xFF
            self._last_seq = seq
            if entry is None:
                stats.unknown_types += 1
                stats.bytes_skipped += len(chunk) + 1
                continue
            unpack = entry[1][size]
            if unpack is None:
                stats.bad_lengths += 1
                stats.bytes_skipped += len(chunk) + 1
                continue
            stats.frames_ok += 1
            out.append(unpack(payload, seq))
        return out

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
