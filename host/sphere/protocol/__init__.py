"""The sphere's wire protocol (protocol/spec.md): packet types, framing, and a streaming decoder.

    from sphere.protocol import FrameDecoder, encode_frame, RawSample
    decoder = FrameDecoder()
    for packet in decoder.feed(chunk_of_bytes):
        ...
    decoder.stats  # crc_errors, oversize, unknown_types, bytes_skipped, seq_gaps, ...

    stream = PacketStream()            # the same, with device time unwrapped: what the daemon,
    for dp in stream.feed(chunk): ...  # captures and calibration use (sphere.protocol.stream)
"""

from sphere.protocol.framing import MAX_FRAME, MAX_PAYLOAD, crc16, encode_frame, encode_payload
from sphere.protocol.decoder import DecoderStats, FrameDecoder
from sphere.protocol.packets import (
    PROTOCOL_VERSION,
    CalibrationBlock,
    CalibrationStep,
    Echo,
    Event,
    GetCalibration,
    GetHello,
    GetStatus,
    Hello,
    Identify,
    LoadCalibration,
    Orientation,
    Packet,
    RawSample,
    Reboot,
    Reply,
    ResetCalibration,
    Result,
    SaveCalibration,
    SetBaud,
    SetCalibration,
    SetFilter,
    SetFreeFall,
    SetStream,
    SetTap,
    Status,
    packet_class,
)
from sphere.protocol.timebase import TimeUnwrapper
from sphere.protocol.stream import DecodedPacket, PacketStream

__all__ = [name for name in dir() if not name.startswith("_")]
