"""Every golden vector in protocol/vectors/frames.txt decodes as the file says, and re-encodes."""

import pytest

from sphere.protocol import encode_frame
from sphere.protocol.decoder import decode_all
from sphere.protocol.packets import packet_class
from sphere.protocol.vectors import load_vectors

VECTORS = load_vectors()
OUTCOME_COUNTER = {
    "oversize": "oversize",
    "framing_error": "framing_errors",
    "crc_error": "crc_errors",
    "unknown_type": "unknown_types",
    "bad_length": "bad_lengths",
}


def test_file_covers_every_packet_type_and_every_outcome():
    from sphere.protocol.packets import ALL_TYPES

    ok_types = {v.type for v in VECTORS if v.outcome == "ok"}
    assert ok_types == {cls.NAME for cls in ALL_TYPES}
    assert {v.outcome for v in VECTORS} == {"ok", *OUTCOME_COUNTER}


@pytest.mark.parametrize("vector", VECTORS, ids=[v.name for v in VECTORS])
def test_vector(vector):
    assert vector.wire.endswith(b"\x00")
    packets, stats = decode_all(vector.wire, vector.direction)
    if vector.outcome == "ok":
        assert stats.errors == 0 and len(packets) == 1
        packet = packets[0]
        assert packet.NAME == vector.type and packet.seq == vector.seq
        fields = packet.fields()
        for key, expected in vector.fields.items():
            assert fields[key] == expected, key
        assert set(fields) == set(vector.fields)
        assert encode_frame(packet, packet.seq) == vector.wire
    else:
        assert packets == []
        assert getattr(stats, OUTCOME_COUNTER[vector.outcome]) == 1
        assert stats.errors == 1
        assert stats.bytes_skipped == len(vector.wire)


@pytest.mark.parametrize("vector", [v for v in VECTORS if v.outcome == "ok"], ids=lambda v: v.name)
def test_vector_is_recognised_after_garbage(vector):
    """Garbage and a delimiter in front never cost the next frame."""
    packets, stats = decode_all(b"\x13\x37\xff\x00" + vector.wire, vector.direction)
    assert len(packets) == 1 and packets[0].NAME == vector.type


def test_packet_built_from_vector_fields_matches_wire():
    """Building the packet from the file's fields (not from decoding) gives the same bytes."""
    for v in VECTORS:
        if v.outcome != "ok":
            continue
        cls = packet_class(v.type)
        fields = dict(v.fields)
        if "data" in fields:
            fields["data"] = bytes.fromhex(fields["data"])
        packet = cls(**fields, seq=v.seq)
        assert encode_frame(packet, v.seq) == v.wire, v.name


def test_version_1_bodies_still_decode():
    """Version 2 appended fields to HELLO and STATUS: a version-1 body (their prefix) decodes with the
    new fields at their defaults, so captures from version-1 firmware still play."""
    from sphere.protocol.framing import encode_payload
    from sphere.protocol.packets import SUPPORTED_VERSIONS, Hello, Status

    assert SUPPORTED_VERSIONS == (1, 2, 3)  # version 3 only added commands (spec §4.1)
    v2 = Hello(2, (0, 2, 0), 7, 0xE5, 0x69, b"H43", 200, 100, 7, 200, 100, 0x21, 0x08, 1, 2)
    v1_body = v2.pack_body()[:19]
    packets, stats = decode_all(encode_payload(Hello.TYPE, 0, v1_body), "device")
    assert stats.errors == 0 and len(packets) == 1
    hello = packets[0]
    assert hello.protocol_version == 2 and hello.hmc5883l_id == tuple(b"H43") and hello.calibration_state == 0x21
    assert (hello.reset_cause, hello.mag_chip, hello.board_profile) == (0, 0, 0)
    status = Status(1000, 7, (1, 2, 3), 4, 5, 6, 7, 1, 0, 300, 0, 9, 10)
    packets, stats = decode_all(encode_payload(Status.TYPE, 1, status.pack_body()[:25]), "device")
    assert stats.errors == 0 and packets[0].i2c_errors == (1, 2, 3) and packets[0].probe_failures == 0
    # any other length is still a bad length
    packets, stats = decode_all(encode_payload(Hello.TYPE, 2, v2.pack_body()[:20]), "device")
    assert packets == [] and stats.bad_lengths == 1
