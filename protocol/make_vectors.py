#!/usr/bin/env python3
"""Writes protocol/vectors/frames.txt from the host codec: `python3 protocol/make_vectors.py`.

The file is committed and is the contract; this script only records how it was made. After a wire
change, re-run it, read the diff, bump PROTOCOL_VERSION, and make the firmware pass the new file.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "host"))

from cobs import cobs  # noqa: E402

from sphere.protocol import packets as p  # noqa: E402
from sphere.protocol.framing import crc16, encode_frame, encode_payload  # noqa: E402


def hexs(b: bytes) -> str:
    return " ".join(f"{x:02x}" for x in b)


def block(name, direction, wire, outcome, comment, packet=None, type_name=None, seq=None):
    lines = [f"# {comment}", f"[{name}]", f"direction = {direction}", f"wire = {hexs(wire)}", f"outcome = {outcome}"]
    if packet is not None:
        lines += [f"type = {packet.NAME}", f"seq = {packet.seq}"]
        for key, value in packet.fields().items():
            if isinstance(value, list):
                value = ",".join(str(v) for v in value)
            lines.append(f"{key} = {value}")
    elif type_name is not None:
        lines += [f"type = {type_name}", f"seq = {seq}"]
    return "\n".join(lines) + "\n"


def ok(name, packet, seq, comment):
    packet.seq = seq
    return block(name, packet.DIRECTION, encode_frame(packet, seq), "ok", comment, packet)


def main() -> None:
    cal = p.SetCalibration(
        gyro_bias=(-12, 7, 3),
        accel_offset=(4, -9, 17),
        accel_scale=(16300, 16420, 16384),
        mag_offset=(-35, 120, -8),
        mag_soft_iron=(16500, -120, 40, -120, 16200, 15, 40, 15, 16390),
    )
    out = [
        "# Golden vectors of the MARG sphere wire protocol, version 2 (format: protocol/spec.md §7).\n"
        "# Made by protocol/make_vectors.py; host tests (tests/host/test_vectors.py) and the firmware's\n"
        "# native tests read this file.\n"
    ]
    out.append(ok("hello", p.Hello(2, (0, 2, 0), 7, 0xE5, 0x69, b"H43", 200, 100, 7, 200, 100, 0x21, 0x01, 1, 0), 0,
                  "HELLO after power-up: all three sensors (HMC5883L), default streams, gyro bias estimated at start, "
                  "power-on reset, aligned board"))
    out.append(ok("hello_no_mag", p.Hello(2, (0, 2, 0), 3, 0xE5, 0x68, b"\0\0\0", 200, 100, 2, 0, 50, 0x10, 0x08, 0, 1),
                  0, "HELLO after a watchdog reset with the magnetometer missing, an invalid EEPROM and the SEN-10724 "
                  "profile (zeros in the body exercise COBS)"))
    out.append(ok("hello_qmc", p.Hello(2, (0, 2, 0), 7, 0xE5, 0x68, b"\0\0\0", 200, 100, 7, 200, 100, 0x01, 0x02, 2, 2),
                  0, "HELLO with a QMC5883L (nothing at 0x1E), external reset, GY-85 profile"))
    out.append(ok("raw_sample", p.RawSample(123456789, 0x0F, (-3, 12, 256), (5, -7, 1), (210, -45, -380)), 17,
                  "RAW_SAMPLE at rest, z up: accel (−3, 12, 256) LSB ≈ (−0.012, 0.047, 1.0) g"))
    out.append(ok("raw_sample_extremes", p.RawSample(0xFFFFFFFF, 0x17, (-4096, 4095, 0), (-32768, 32767, 0), (-4096, 2047, -2048)), 255,
                  "RAW_SAMPLE at the limits: saturated accel and gyro, magnetometer x overflow (−4096), seq 255, t_us about to wrap, tap active"))
    out.append(ok("raw_sample_zero", p.RawSample(0, 0, (0, 0, 0), (0, 0, 0), (0, 0, 0)), 0,
                  "RAW_SAMPLE of zeros: a payload with many 0x00 bytes"))
    out.append(ok("raw_sample_stale", p.RawSample(5005000, 0x47, (-3, 12, 256), (2875, -7, 1), (210, -45, -380)), 18,
                  "RAW_SAMPLE whose gyro read failed: the last good gyro value held and flagged gyro_stale"))
    out.append(ok("orientation_identity", p.Orientation(5000, 0x01, (16384, 0, 0, 0)), 1,
                  "ORIENTATION: identity quaternion, magnetometer used"))
    out.append(ok("orientation_turned", p.Orientation(2000000, 0x02, (11585, 0, 0, 11585)), 42,
                  "ORIENTATION: 90° about z (w = z = 0.7071 → 11585 in Q14), accelerometer rejected"))
    out.append(ok("orientation_gyro_missing", p.Orientation(9000000, 0x12, (11585, 0, 0, 11585)), 43,
                  "ORIENTATION held while the gyroscope is missing (gyro_missing), accelerometer rejected"))
    out.append(ok("orientation_prev", p.Orientation(9005000, 0x41, (11585, 0, 0, 11585)), 44,
                  "ORIENTATION: this update used the magnetometer, the one before rejected the accelerometer "
                  "(prev_accel_rejected)"))
    out.append(ok("event_single_tap", p.Event(777000, 1, 0xC3, 0x01, -1), 3,
                  "EVENT single tap on z, spike negative (INT_SOURCE = DATA_READY|SINGLE_TAP|watermark|overrun bits as read)"))
    out.append(ok("event_double_tap", p.Event(1777000, 2, 0xE0, 0x04, 1), 4, "EVENT double tap on x"))
    out.append(ok("event_free_fall", p.Event(2500000, 3, 0x84, 0x00, 0), 5, "EVENT free fall (toss)"))
    out.append(ok("status", p.Status(1000000, 0x05, (0, 12, 1), 2, 3, 0, 1, 0x07, 0, 412, 0, 57, 1), 200,
                  "STATUS: gyroscope missing (lost once after 12 failed transactions, 57 failed re-probes), load 41.2 %"))
    out.append(ok("reply_ok", p.Reply(9, p.SetStream.TYPE, p.Result.OK), 6, "REPLY ok to SET_STREAM seq 9"))
    out.append(ok("reply_bad_value", p.Reply(10, p.SetStream.TYPE, p.Result.BAD_VALUE), 7,
                  "REPLY bad_value: raw rate that does not divide 200"))
    out.append(ok("reply_unknown_command", p.Reply(11, 0x7E, p.Result.UNKNOWN_COMMAND), 8,
                  "REPLY unknown_command to type 0x7E"))
    out.append(ok("reply_calibration", p.Reply(12, p.GetCalibration.TYPE, p.Result.OK, data=cal.pack_body() + bytes([0x0F])), 9,
                  "REPLY to GET_CALIBRATION: 42-byte block then calibration_state"))
    saved = p.settings_block((p.SetStream(0x03, 100, 50), p.SetTap(40, 32, 0, 0, 0x01), p.SetFreeFall(8, 40), p.SetFilter(60)))
    out.append(ok("reply_settings", p.Reply(13, p.GetSettings.TYPE, p.Result.OK, data=saved + bytes([p.SETTINGS_SAVED])), 10,
                  "REPLY to GET_SETTINGS: 14-byte settings block (raw 100 Hz, orientation 50 Hz, no status; tap 2.5 g "
                  "on z only, no double tap; free fall 0.5 g for 200 ms; β 0.060) then settings_state saved"))
    out.append(ok("reply_echo", p.Reply(14, p.Echo.TYPE, p.Result.OK, data=(4000123456).to_bytes(4, "little")), 11,
                  "REPLY to ECHO: device_t_us 4000123456 (version 3)"))
    # host → device
    out.append(ok("cmd_get_hello", p.GetHello(), 0, "GET_HELLO"))
    out.append(ok("cmd_set_stream", p.SetStream(0x07, 200, 100), 1, "SET_STREAM: raw 200 Hz, orientation 100 Hz, status"))
    out.append(ok("cmd_set_stream_bad_rate", p.SetStream(0x01, 30, 0), 2,
                  "SET_STREAM raw at 30 Hz: a valid frame that the device answers with bad_value"))
    out.append(ok("cmd_set_tap", p.SetTap(48, 32, 80, 240, 0x07), 3, "SET_TAP: 3 g, 20 ms, 100 ms latency, 300 ms window, x y z"))
    out.append(ok("cmd_set_free_fall", p.SetFreeFall(7, 30), 4, "SET_FREE_FALL: 0.44 g for 150 ms"))
    out.append(ok("cmd_set_filter", p.SetFilter(41), 5, "SET_FILTER β = 0.041"))
    out.append(ok("cmd_calibration_step", p.CalibrationStep(1, 1), 6, "CALIBRATION_STEP start gyro_bias"))
    out.append(ok("cmd_set_calibration", cal, 7, "SET_CALIBRATION with every field non-trivial"))
    out.append(ok("cmd_get_calibration", p.GetCalibration(), 8, "GET_CALIBRATION"))
    out.append(ok("cmd_save_calibration", p.SaveCalibration(), 9, "SAVE_CALIBRATION"))
    out.append(ok("cmd_load_calibration", p.LoadCalibration(), 10, "LOAD_CALIBRATION"))
    out.append(ok("cmd_reset_calibration", p.ResetCalibration(), 11, "RESET_CALIBRATION"))
    out.append(ok("cmd_identify", p.Identify(5), 12, "IDENTIFY for 5 s"))
    out.append(ok("cmd_reboot", p.Reboot(p.REBOOT_MAGIC), 13, "REBOOT with its magic"))
    out.append(ok("cmd_get_status", p.GetStatus(), 14, "GET_STATUS"))
    out.append(ok("cmd_set_board", p.SetBoard(1), 17, "SET_BOARD: SparkFun SEN-10724 sensor stick"))
    out.append(ok("cmd_get_settings", p.GetSettings(), 18, "GET_SETTINGS"))
    out.append(ok("cmd_save_settings", p.SaveSettings(), 19, "SAVE_SETTINGS"))
    out.append(ok("cmd_clear_settings", p.ClearSettings(), 20, "CLEAR_SETTINGS"))
    out.append(ok("cmd_set_baud", p.SetBaud(1000000), 21, "SET_BAUD 1000000 (version 3)"))
    out.append(ok("cmd_set_baud_bad_rate", p.SetBaud(230400), 22,
                  "SET_BAUD 230400: not exact on 16 MHz, a valid frame the device answers with bad_value"))
    out.append(ok("cmd_echo", p.Echo(), 23, "ECHO (version 3)"))

    # broken frames
    good = p.RawSample(123456789, 0x0F, (-3, 12, 256), (5, -7, 1), (210, -45, -380))
    payload = bytes([good.TYPE, 17]) + good.pack_body()
    payload += (crc16(payload)).to_bytes(2, "little")
    flipped = bytearray(payload)
    flipped[5] ^= 0x10
    out.append(block("crc_error", "device", cobs.encode(bytes(flipped)) + b"\0", "crc_error",
                     "RAW_SAMPLE with one bit flipped in the body: CRC fails"))
    bad_crc = bytearray(payload)
    bad_crc[-1] ^= 0xFF
    out.append(block("crc_error_in_crc", "device", cobs.encode(bytes(bad_crc)) + b"\0", "crc_error",
                     "RAW_SAMPLE whose CRC bytes are damaged"))
    out.append(block("framing_error_cobs", "device", bytes([0x09, 0x02, 0x11, 0x00]), "framing_error",
                     "COBS code byte 0x09 points past the end of the chunk"))
    short = bytes([0x02, 0x11])
    out.append(block("framing_error_short", "device", cobs.encode(short) + b"\0", "framing_error",
                     "payload of two bytes: shorter than type, seq and CRC"))
    out.append(block("oversize", "device", bytes(range(1, 71)) + b"\0", "oversize",
                     "70 bytes without a delimiter: longer than any frame (65 + 1)"))
    out.append(block("unknown_type", "device", encode_payload(0x3F, 21, b"\x01\x02\x03"), "unknown_type",
                     "CRC-good frame of type 0x3F, unknown in version 2: dropped, seq still counted",
                     type_name="0x3F", seq=21))
    out.append(block("bad_length", "device", encode_payload(p.RawSample.TYPE, 22, good.pack_body()[:-1]), "bad_length",
                     "RAW_SAMPLE with a 22-byte body (23 expected)", type_name="RAW_SAMPLE", seq=22))
    out.append(block("cmd_bad_length", "host", encode_payload(p.SetFilter.TYPE, 15, b"\x29"), "bad_length",
                     "SET_FILTER with one body byte: the device replies bad_length", type_name="SET_FILTER", seq=15))
    out.append(block("cmd_unknown_type", "host", encode_payload(0x7E, 16, b""), "unknown_type",
                     "command 0x7E: the device replies unknown_command", type_name="0x7E", seq=16))
    path = Path(__file__).resolve().parent / "vectors" / "frames.txt"
    path.write_text("\n".join(out))
    print(f"wrote {path} ({len(out) - 1} vectors)")


if __name__ == "__main__":
    main()
