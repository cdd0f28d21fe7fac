"""The streaming decoder: chunking independence, resynchronisation, counters, fuzzing."""

import random

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import pytest

from sphere.protocol import FrameDecoder, encode_frame
from sphere.protocol.decoder import decode_all
from sphere.protocol.framing import MAX_ENCODED, encode_payload
from sphere.protocol.packets import Event, Hello, Orientation, RawSample, Status

int16 = st.integers(-32768, 32767)
vec3 = st.tuples(int16, int16, int16)
raw_samples = st.builds(RawSample, st.integers(0, 2**32 - 1), st.integers(0, 31), vec3, vec3, vec3)
orientations = st.builds(Orientation, st.integers(0, 2**32 - 1), st.integers(0, 15), st.tuples(int16, int16, int16, int16))
events = st.builds(Event, st.integers(0, 2**32 - 1), st.integers(1, 3), st.integers(0, 255), st.integers(0, 7), st.integers(-1, 1))
packets = st.one_of(raw_samples, orientations, events)


def stream_of(pkts, first_seq=0):
    return b"".join(encode_frame(p, (first_seq + i) & 0xFF) for i, p in enumerate(pkts))


def feed_in_pieces(data, cuts):
    decoder = FrameDecoder()
    out = []
    pos = 0
    for cut in sorted(cuts) + [len(data)]:
        out += decoder.feed(data[pos:cut])
        pos = max(pos, cut)
    return out, decoder.stats


@given(st.lists(packets, min_size=1, max_size=40), st.lists(st.integers(0, 2000), max_size=30))
def test_chunking_does_not_change_the_result(pkts, cuts):
    data = stream_of(pkts)
    whole, whole_stats = decode_all(data)
    pieces, piece_stats = feed_in_pieces(data, [c % (len(data) + 1) for c in cuts])
    assert pieces == whole
    assert piece_stats == whole_stats
    assert [p.fields() for p in whole] == [p.fields() for p in pkts]


def test_one_byte_at_a_time_equals_all_at_once():
    rng = random.Random(7)
    pkts = [RawSample(i * 5000, 15, (rng.randint(-300, 300),) * 3, (i, -i, 0), (100, 0, -100)) for i in range(300)]
    data = stream_of(pkts) + bytes(rng.randrange(256) for _ in range(500)) + b"\x00" + stream_of(pkts[:10], 44)
    decoder = FrameDecoder()
    slow = [p for b in data for p in decoder.feed(bytes([b]))]
    fast, stats = decode_all(data)
    assert slow == fast and decoder.stats == stats
    assert len(fast) >= 310


def test_bytes_in_counts_every_byte_fed_whenever_it_is_read():
    """A byte fed alone inside a frame is only kept (the byte-at-a-time path): ``stats`` still counts it when read,
    and a restart counts the cut frame's bytes."""
    data = stream_of([Orientation(i, 1, (16384, 0, 0, 0)) for i in range(3)])
    decoder = FrameDecoder()
    for i, b in enumerate(data, 1):
        decoder.feed(bytes([b]))
        assert decoder.stats.bytes_in == i
    decoder.feed(data[:5])
    decoder.restart()
    decoder.feed(b"\x07")
    assert decoder.stats.bytes_in == len(data) + 6 and decoder.stats.frames_ok == 3


def test_every_packet_type_decodes_as_its_fields_say():
    """The per-class unpacker written out from the field table (the decoder's hot path) gives what the table
    says: every field, in order, a tuple for an array; the wrong length is refused."""
    import struct

    from sphere.protocol.packets import ALL_TYPES, Reply

    for cls in ALL_TYPES:
        values = list(range(1, sum(f.count for f in cls.FIELDS) + 1))
        body = cls._struct.pack(*values)
        p = cls.unpack_body(body, 9)
        i = 0
        for f in cls.FIELDS:
            want = values[i] if f.count == 1 else tuple(values[i : i + f.count])
            assert getattr(p, f.name) == want, (cls.NAME, f.name)
            i += f.count
        assert p.seq == 9 and p.pack_body() == body
        if cls is Reply:  # data of any length may follow a REPLY's fields
            continue
        with pytest.raises(struct.error):
            cls.unpack_body(body + b"\x00" * 200)


def test_sequence_gaps_are_counted():
    pkts = [Orientation(i, 1, (16384, 0, 0, 0)) for i in range(10)]
    data = b"".join(encode_frame(p, s) for p, s in zip(pkts, [250, 251, 252, 255, 0, 1, 5, 6, 7, 8]))
    out, stats = decode_all(data)
    assert len(out) == 10
    assert stats.seq_gaps == 2 and stats.frames_lost == 2 + 3


def test_unknown_type_still_counts_its_sequence_number():
    data = encode_frame(Orientation(1, 0, (16384, 0, 0, 0)), 1) + encode_payload(0x3E, 2, b"xyz")
    data += encode_frame(Orientation(2, 0, (16384, 0, 0, 0)), 3)
    out, stats = decode_all(data)
    assert len(out) == 2 and stats.unknown_types == 1 and stats.seq_gaps == 0


@pytest.mark.parametrize("size", [1, 7, 100, 597])
def test_a_chunk_too_long_counts_the_same_however_it_comes_and_whenever_it_is_read(size):
    """Bytes without a delimiter are only kept when they come: a chunk past the longest frame is still counted
    once, with every byte skipped, when the stats are read before any delimiter, and the next frame survives."""
    frame = encode_frame(Orientation(9, 0, (16384, 0, 0, 0)), 0)
    junk = bytes(range(1, 200)) * 3
    decoder = FrameDecoder()
    for i in range(0, len(junk), size):
        assert not decoder.feed(junk[i : i + size])
    stats = decoder.stats
    assert (stats.oversize, stats.bytes_skipped, stats.bytes_in) == (1, len(junk), len(junk))
    assert [p.t_us for p in decoder.feed(b"\x00" + frame)] == [9]
    assert (stats.oversize, stats.bytes_skipped, stats.frames_ok) == (1, len(junk) + 1, 1)
    assert decoder.stats == decode_all(junk + b"\x00" + frame)[1]


def test_device_restart_is_not_a_gap():
    hello = Hello(1, (0, 1, 0), 7, 0xE5, 0x69, b"H43", 200, 75, 7, 200, 100, 0)
    data = encode_frame(hello, 0) + stream_of([Status(0, 7, (0, 0, 0), 0, 0, 0, 0, 0, 0, 0, 0)] * 5, 1)
    out, stats = decode_all(data + data)
    assert len(out) == 12 and stats.seq_gaps == 0 and stats.restarts == 1


def test_oversize_chunk_is_dropped_once_and_next_frame_survives():
    frame = encode_frame(Orientation(9, 0, (16384, 0, 0, 0)), 0)
    junk = bytes(range(1, 200)) * 3  # no zero byte: one long chunk
    decoder = FrameDecoder()
    out = []
    for i in range(0, len(junk), 7):
        out += decoder.feed(junk[i : i + 7])
    out += decoder.feed(b"\x00" + frame)
    assert [p.t_us for p in out] == [9]
    assert decoder.stats.oversize == 1
    assert decoder.stats.bytes_skipped == len(junk) + 1
    assert MAX_ENCODED == 65


def test_host_direction_does_not_accept_device_packets():
    out, stats = decode_all(encode_frame(Orientation(1, 0, (16384, 0, 0, 0)), 0), direction="host")
    assert out == [] and stats.unknown_types == 1


# -- fuzzing: valid frames mixed with corruption ---------------------------------------------------

corruption = st.one_of(
    st.tuples(st.just("noise"), st.binary(min_size=1, max_size=120)),
    st.tuples(st.just("flip"), st.integers(0, 10_000), st.integers(0, 7)),
    st.tuples(st.just("truncate"), st.integers(1, 30)),
    st.tuples(st.just("insert"), st.integers(0, 10_000), st.binary(min_size=1, max_size=5)),
)


@pytest.mark.slow
@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(packets, st.lists(corruption, max_size=2)), min_size=1, max_size=25))
def test_every_untouched_frame_is_decoded_and_nothing_raises(items):
    """Build a stream frame by frame, damaging some; every frame whose bytes are intact and which
    starts right after a delimiter (or at the start) must come out, in order."""
    stream = bytearray()
    expected = []
    for seq, (packet, damages) in enumerate(items):
        frame = bytearray(encode_frame(packet, seq & 0xFF))
        touched = False
        prefix = bytearray()
        for damage in damages:
            kind = damage[0]
            if kind == "noise":
                prefix += damage[1]
            elif kind == "flip":
                frame[damage[1] % len(frame)] ^= 1 << damage[2]
                touched = True
            elif kind == "truncate":
                del frame[-min(damage[1], len(frame) - 1) :]
                touched = True
            elif kind == "insert":
                at = damage[1] % len(frame)
                frame[at:at] = damage[2]
                touched = True
        stream += prefix
        starts_clean = not stream or stream[-1] == 0
        stream += frame
        if not touched and starts_clean:
            expected.append((seq & 0xFF, packet.fields()))
    decoder = FrameDecoder()
    out = []
    for i in range(0, len(stream), 13):
        out += decoder.feed(bytes(stream[i : i + 13]))
    got = [(p.seq, p.fields()) for p in out]
    # every expected frame appears, in order (a damaged chunk may, very rarely, still pass the CRC)
    it = iter(got)
    assert all(any(g == e for g in it) for e in expected), (expected, got)
    stats = decoder.stats
    assert stats.frames_ok == len(out)


@given(st.lists(packets, min_size=2, max_size=10), st.integers(1, 400))
def test_a_stream_that_takes_over_from_a_probe_mid_frame_loses_nothing(pkts, cut):
    """The serial source's discovery probe decodes up to the HELLO and hands over to the link's stream: the frame the
    probe's last read cut in two is finished by the new stream (FrameDecoder.pending, PacketStream.adopt), not counted
    as a framing error and a sequence gap."""
    from sphere.daemon.scripted_sphere import hello_packet
    from sphere.protocol import PacketStream

    data = encode_frame(hello_packet(), 7) + stream_of(pkts, first_seq=8)
    cut = min(cut, len(data) - 1)
    probe = PacketStream("device")
    got = probe.feed(data[:cut])
    if not got:  # the probe has not the HELLO whole yet: it reads on
        return
    stream = PacketStream("device")
    adopted = stream.adopt([d.packet for d in got], probe.decoder.pending())
    rest = stream.feed(data[cut:])
    assert [(d.packet.NAME, d.packet.seq) for d in adopted + rest] == [("HELLO", 7)] + [
        (p.NAME, 8 + i) for i, p in enumerate(pkts)]
    s = stream.stats
    assert (s.framing_errors, s.crc_errors, s.seq_gaps, s.bytes_skipped) == (0, 0, 0, 0)
