"""Framing (spec §2): payload = type, seq, body, CRC-16/CCITT-FALSE (LE); wire = COBS(payload) 0x00."""

from __future__ import annotations

import binascii
import struct

from cobs import cobs

from sphere.errors import SphereError

MAX_PAYLOAD = 64
#: Longest COBS encoding of a payload, before its delimiter.
MAX_ENCODED = MAX_PAYLOAD + (MAX_PAYLOAD + 253) // 254
#: Longest frame on the wire, delimiter included.
MAX_FRAME = MAX_ENCODED + 1
MIN_PAYLOAD = 4

#: CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final XOR; check("123456789") = 0x29B1.
#: The standard library's CRC-CCITT (binascii.crc_hqx: poly 0x1021, MSB first, no final XOR) from 0xFFFF is
#: exactly that, in C, without a Python wrapper per call (the decoder's hot path calls it directly).
CRC16_INIT = 0xFFFF


def crc16(data: bytes) -> int:
    return binascii.crc_hqx(data, CRC16_INIT)

_HEADER = struct.Struct("<BB")
_CRC = struct.Struct("<H")


class FrameTooLong(SphereError, ValueError):
    pass


def encode_payload(type_: int, seq: int, body: bytes) -> bytes:
    """The wire frame for one payload: COBS-encoded, with its CRC and the trailing 0x00."""
    raw = _HEADER.pack(type_, seq & 0xFF) + body
    raw += _CRC.pack(crc16(raw))
    if len(raw) > MAX_PAYLOAD:
        raise FrameTooLong(f"payload of {len(raw)} bytes exceeds the protocol's {MAX_PAYLOAD}")
    return cobs.encode(raw) + b"\x00"


def encode_frame(packet, seq: int) -> bytes:
    """The wire frame for a packet object (see :mod:`sphere.protocol.packets`)."""
    return encode_payload(packet.TYPE, seq, packet.pack_body())
