"""What `sphere monitor` shows, from a byte stream with a damaged frame in it: counts and rates per
packet type, flags, values in physical units, events as they come, and the decoder's link counters."""

from sphere.link.capture import DecodedPacket
from sphere.link.monitor import LinkMonitor
from sphere.protocol import Event, FrameDecoder, Orientation, RawSample, encode_frame
from sphere.protocol.timebase import TimeUnwrapper
from sphere.protocol.vectors import load_vectors

HELLO = next(v.wire for v in load_vectors() if v.name == "hello")


def test_view_of_a_stream():
    wire = bytearray(HELLO)
    seq = 1
    for i in range(200):  # one second at 200 Hz: level, turning at 14.375 LSB = 1 °/s about z
        wire += encode_frame(RawSample(t_us=i * 5000, flags=0b1111, accel=(0, 0, 256), gyro=(0, 0, 144),
                                       mag=(0, 218, -491)), seq)
        seq += 1
        if i % 2 == 0:
            wire += encode_frame(Orientation(t_us=i * 5000, flags=1, quat=(16384, 0, 0, 0)), seq)
            seq += 1
    wire += encode_frame(Event(t_us=1_000_000, event=2, int_source=0x60, act_tap_status=1, tap_sign=1), seq)
    bad = bytearray(encode_frame(RawSample(t_us=1_005_000, flags=15, accel=(0, 0, 256), gyro=(0, 0, 0),
                                           mag=(0, 0, 0)), seq + 1))
    bad[5] ^= 0xFF  # a damaged frame: the CRC catches it
    wire += bad
    dec, unwrap, mon = FrameDecoder("device"), TimeUnwrapper(), None
    mon = LinkMonitor(dec.stats)
    lines_out = []
    for i in range(0, len(wire), 64):  # as chunks arrive over one second of wall time
        for p in dec.feed(bytes(wire[i:i + 64])):
            t = getattr(p, "t_us", None)
            line = mon.packet(DecodedPacket(p, unwrap(t) if t is not None else None), i / len(wire))
            if line:
                lines_out.append(line)
    assert lines_out[0].startswith("HELLO seq 0: firmware 0.2.0, protocol 2, sensors adxl345, itg3200, hmc5883l")
    assert lines_out[-1] == "event 1.000 s  double_tap (z)"
    view = "\n".join(mon.lines(1.0))
    assert "RAW_SAMPLE 200 (200/s)" in view and "ORIENTATION 100 (100/s)" in view  # per wall second
    assert "flags: accel_ok gyro_ok mag_ok mag_fresh" in view
    assert "accel g    +0.000  +0.000  +1.000   |a| 1.000" in view
    assert "gyro °/s    +0.00   +0.00  +10.02" in view  # 144 LSB / 14.375
    assert "heading    +0.0°" in view and "mag_used" in view
    assert "CRC errors 1" in view and "events: 1.000 s  double_tap (z)" in view
    assert mon.summary(1.0).startswith("EVENT 1/s, HELLO 1/s, ORIENTATION 100/s, RAW_SAMPLE 200/s; flags accel_ok")
