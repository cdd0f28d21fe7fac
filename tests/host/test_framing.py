"""Framing checked against independent implementations written here from the spec's words."""

from hypothesis import given
from hypothesis import strategies as st

from sphere.protocol import MAX_FRAME, MAX_PAYLOAD, crc16
from sphere.protocol.framing import FrameTooLong, encode_payload
from sphere.protocol.packets import RawSample, SetCalibration, CalibrationBlock


def crc16_ccitt_false_bitwise(data: bytes) -> int:
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else crc << 1
            crc &= 0xFFFF
    return crc


def cobs_decode_by_hand(enc: bytes) -> bytes:
    out, i = bytearray(), 0
    while i < len(enc):
        code = enc[i]
        out += enc[i + 1 : i + code]
        i += code
        if code < 0xFF and i < len(enc):
            out.append(0)
    return bytes(out)


def test_crc_check_value():
    assert crc16(b"123456789") == 0x29B1
    assert crc16_ccitt_false_bitwise(b"123456789") == 0x29B1


@given(st.binary(max_size=80))
def test_crc_matches_bitwise(data):
    assert crc16(data) == crc16_ccitt_false_bitwise(data)


def test_cobs_examples_from_the_paper():
    from cobs import cobs

    assert cobs.encode(b"\x00") == b"\x01\x01"
    assert cobs.encode(b"\x11\x22\x00\x33") == b"\x03\x11\x22\x02\x33"
    assert cobs.encode(b"\x11\x00\x00\x00") == b"\x02\x11\x01\x01\x01"


@given(st.integers(0, 255), st.binary(max_size=MAX_PAYLOAD - 4))
def test_frame_layout(seq, body):
    wire = encode_payload(0x02, seq, body)
    assert wire[-1] == 0 and 0 not in wire[:-1]
    assert len(wire) <= MAX_FRAME
    payload = cobs_decode_by_hand(wire[:-1])
    assert payload[0] == 0x02 and payload[1] == seq and payload[2:-2] == body
    assert int.from_bytes(payload[-2:], "little") == crc16_ccitt_false_bitwise(payload[:-2])


def test_longest_payload_fits_and_longer_is_refused():
    assert len(encode_payload(0x06, 0, bytes(MAX_PAYLOAD - 4))) == MAX_FRAME
    try:
        encode_payload(0x06, 0, bytes(MAX_PAYLOAD - 3))
    except FrameTooLong as e:
        assert "64" in str(e)
    else:
        raise AssertionError("a payload over 64 bytes was encoded")


def test_every_packet_type_fits():
    from sphere.protocol.packets import ALL_TYPES, body_sizes

    for cls in ALL_TYPES:
        assert max(body_sizes(cls)) + 4 <= MAX_PAYLOAD, cls.NAME


def test_calibration_default_is_identity():
    block = CalibrationBlock.default()
    assert block.accel_scale == (16384,) * 3
    assert block.mag_soft_iron[0::4] == (16384,) * 3
    assert SetCalibration.body_size() == 42 == CalibrationBlock.SIZE
    assert RawSample.body_size() == 23
