"""`sphere calibrate`: gyro bias, accelerometer six-position and magnetometer ellipsoid calibration."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

HELP = "calibrate the sphere's sensors (guided on a port, or offline from a capture)"
DESCRIPTION = """\
Computes the calibration block (protocol spec §5.2) from raw samples: gyro bias from still phases,
accelerometer offset and scale from six still poses (each face of the sphere up), magnetometer hard and
soft iron from an ellipsoid fit over readings taken while turning the sphere every way. Prints the
result with the fit residual and the field norm before and after.

--port PORT guides you through the steps with progress shown, sends the result to the sphere
(SET_CALIBRATION) and asks it to save (SAVE_CALIBRATION). --capture FILE does the same offline from a
capture recorded with `sphere capture` (lay the sphere still on six faces, a few seconds each, and turn
it through every direction for ~30 s); nothing is sent."""

STILL_S = 3.0
FACE_S = 2.0
TURN_S = 30.0
FACES = ("+x up", "−x up", "+y up", "−y up", "+z up (upright)", "−z up (upside down)")


def add_arguments(p) -> None:
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--port", help="the sphere's serial port: guided calibration, result sent and saved")
    src.add_argument("--capture", metavar="FILE", help="a capture file (sphere capture): offline, nothing is sent")
    p.add_argument("--baud", type=int, default=115200)
    p.add_argument("--json", metavar="OUT", help="write the result as JSON")
    p.add_argument("--plot", metavar="PNG", help="write the magnetometer cloud before/after as a PNG")
    p.add_argument("--save-capture", metavar="FILE", help="with --port: also keep the session's bytes as a capture")
    p.add_argument("--no-save", action="store_true", help="with --port: apply on the device but do not save to EEPROM")
    p.add_argument("--yes", action="store_true", help="with --port: do not wait for Enter between steps")


def block_from(cal) -> dict:
    """The SET_CALIBRATION fields (integers, spec §5.2) for a :class:`sphere.calibration.Calibration`;
    parts that could not be computed keep the defaults."""
    q14 = 16384

    def i16(v):
        return int(np.clip(np.rint(v), -32768, 32767))

    out = {"gyro_bias": (0, 0, 0), "accel_offset": (0, 0, 0), "accel_scale": (q14,) * 3, "mag_offset": (0, 0, 0),
           "mag_soft_iron": (q14, 0, 0, 0, q14, 0, 0, 0, q14)}
    if cal.gyro is not None:
        out["gyro_bias"] = tuple(i16(v) for v in cal.gyro.bias_lsb)
    if cal.accel is not None:
        out["accel_offset"] = tuple(i16(v) for v in cal.accel.offset_lsb)
        out["accel_scale"] = tuple(i16(v * q14) for v in cal.accel.gain)
    if cal.mag is not None:
        out["mag_offset"] = tuple(i16(v) for v in cal.mag.hard_iron_lsb)
        if np.all(np.abs(cal.mag.soft_iron) < 32767 / q14):
            out["mag_soft_iron"] = tuple(i16(v * q14) for v in cal.mag.soft_iron.ravel())
        else:
            cal.notes.append("mag: soft-iron matrix does not fit Q14 (|entry| ≥ 2); identity kept")
    return out


def raw_arrays(packets):
    """(t_s, accel, gyro, mag_fresh) arrays in chip units from decoded RAW_SAMPLE packets."""
    t, acc, gyr, mag = [], [], [], []
    for dp in packets:
        p = getattr(dp, "packet", dp)
        if p.NAME != "RAW_SAMPLE":
            continue
        flags = p.flags
        if not (flags & 1 and flags & 2):
            continue
        tt = getattr(dp, "t_us", None)
        t.append((tt if tt is not None else p.t_us) * 1e-6)
        acc.append(p.accel)
        gyr.append(p.gyro)
        if flags & 4 and flags & 8:
            mag.append(p.mag)
    return (np.array(t, float), np.array(acc, float).reshape(-1, 3), np.array(gyr, float).reshape(-1, 3),
            np.array(mag, float).reshape(-1, 3))


def report(cal, block) -> str:
    lines = []
    if cal.gyro is not None:
        g = cal.gyro
        lines.append(f"gyro bias: {np.round(g.bias_lsb, 1).tolist()} LSB = {np.round(g.bias_lsb / 14.375, 3).tolist()} °/s "
                     f"(noise {np.round(g.noise_lsb, 1).tolist()} LSB, {g.samples} samples)")
    if cal.accel is not None:
        a = cal.accel
        lines.append(f"accel: offset {np.round(a.offset_lsb, 1).tolist()} LSB, scale {np.round(a.gain, 4).tolist()}, "
                     f"‖a‖ residual {a.residual_lsb:.2f} LSB over {a.poses} poses")
    if cal.mag is not None:
        m = cal.mag
        lines.append(f"mag: hard iron {np.round(m.hard_iron_lsb, 1).tolist()} LSB, soft iron "
                     f"{np.round(m.soft_iron, 3).tolist()}")
        lines.append(f"     fit residual {100 * m.residual:.2f} % of the field; field norm before "
                     f"{m.norm_before[0]:.0f} ± {m.norm_before[1]:.0f} LSB, after {m.norm_after[0]:.0f} ± "
                     f"{m.norm_after[1]:.0f} LSB ({m.radius_lsb / 10.9:.1f} µT)")
    for n in cal.notes:
        lines.append(f"note: {n}")
    lines.append("SET_CALIBRATION block: " + json.dumps({k: list(v) for k, v in block.items()}))
    return "\n".join(lines)


def _finish(args, cal, mag) -> dict:
    block = block_from(cal)
    print(report(cal, block))
    if args.json:
        Path(args.json).write_text(json.dumps({"calibration": cal.as_dict(), "block": {k: list(v) for k, v in block.items()}},
                                              indent=2))
        print(f"wrote {args.json}", file=sys.stderr)
    if args.plot and cal.mag is not None:
        from sphere.calibration import plot_mag_cloud

        plot_mag_cloud(mag, cal.mag, args.plot)
        print(f"wrote {args.plot}", file=sys.stderr)
    return block


def run(args) -> int:
    if args.capture:
        return _run_capture(args)
    return _run_port(args)


def _run_capture(args) -> int:
    from sphere import calibration
    from sphere.capture import CaptureError, CaptureFile

    try:
        cap = CaptureFile(args.capture)
        t, acc, gyr, mag = raw_arrays(cap.packets())
    except CaptureError as e:
        print(f"sphere calibrate: {e}", file=sys.stderr)
        return 2
    if len(t) < 50:
        print(f"sphere calibrate: {args.capture} holds {len(t)} raw samples; record raw samples with "
              "`sphere capture` while following the steps in `sphere calibrate --help`", file=sys.stderr)
        return 2
    rate = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 200.0
    print(f"{len(t)} raw samples at {rate:.0f} Hz, {len(mag)} fresh magnetometer samples", file=sys.stderr)
    cal = calibration.from_capture(acc, gyr, mag if len(mag) else np.zeros((0, 3)), rate)
    _finish(args, cal, mag)
    return 0 if (cal.gyro or cal.accel or cal.mag) else 1


class _Link:
    """A minimal command/reply link over the serial port, feeding RAW_SAMPLEs to a collector."""

    def __init__(self, port, writer=None):
        from sphere.protocol import FrameDecoder

        self.port = port
        self.decoder = FrameDecoder("device")
        self.writer = writer
        self.seq = 0
        self.raw = []

    def pump(self, seconds: float):
        end = time.monotonic() + seconds
        out = []
        while time.monotonic() < end:
            data = self.port.read(max(1, self.port.in_waiting or 1))
            if not data:
                continue
            if self.writer:
                self.writer.write(data)
            for p in self.decoder.feed(data):
                out.append(p)
                if p.NAME == "RAW_SAMPLE":
                    self.raw.append(p)
        return out

    def command(self, packet, timeout_s: float = 1.0):
        from sphere.protocol import encode_frame

        self.seq = (self.seq + 1) & 0xFF
        self.port.write(encode_frame(packet, self.seq))
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            for p in self.pump(0.05):
                if p.NAME == "REPLY" and p.cmd_seq == self.seq and p.cmd_type == packet.TYPE:
                    return p
        return None


def _record(link, seconds: float, label: str):
    start = len(link.raw)
    t0 = time.monotonic()
    while (el := time.monotonic() - t0) < seconds:
        link.pump(0.1)
        n = len(link.raw) - start
        bar = "#" * int(20 * el / seconds)
        print(f"\r  {label}: [{bar:<20}] {el:4.1f}/{seconds:.0f} s, {n} samples", end="", file=sys.stderr)
    print(file=sys.stderr)
    return link.raw[start:]


def _run_port(args) -> int:
    from sphere import calibration
    from sphere.protocol import GetHello, SaveCalibration, SetCalibration
    from sphere.serial_link import PortError, open_port

    try:
        port = open_port(args.port, args.baud)
    except PortError as e:
        print(f"sphere calibrate: {e}", file=sys.stderr)
        return 2
    writer = None
    if args.save_capture:
        from sphere.capture import CaptureWriter

        writer = CaptureWriter(args.save_capture)
    wait = (lambda msg: print(msg, file=sys.stderr)) if args.yes else (lambda msg: input(msg + " — press Enter "))
    try:
        link = _Link(port, writer)
        hello = [p for p in link.pump(0.6) if p.NAME == "HELLO"]
        if not hello:
            link.command(GetHello())
            link.pump(0.3)
        if not link.raw:
            link.pump(1.0)
        if not link.raw:
            print("sphere calibrate: no RAW_SAMPLE from the sphere; is the raw stream on (SET_STREAM)?", file=sys.stderr)
            return 1
        print("1/3 gyro bias: put the sphere down and do not touch it.", file=sys.stderr)
        wait("   ready?")
        still = _record(link, STILL_S, "still")
        faces = []
        print("2/3 accelerometer: lay the sphere on each face in turn, still.", file=sys.stderr)
        for i, face in enumerate(FACES, 1):
            wait(f"   face {i}/6: {face}")
            faces.append(_record(link, FACE_S, face))
        print("3/3 magnetometer: turn the sphere slowly through every direction (figure eights, all axes).",
              file=sys.stderr)
        wait("   ready?")
        turning = _record(link, TURN_S, "turning")
        _, g_still, gyr_still, _ = raw_arrays(still)
        cal = calibration.Calibration()
        try:
            cal.gyro = calibration.gyro_bias(gyr_still)
        except ValueError as e:
            cal.notes.append(f"gyro: {e}")
        try:
            means = [raw_arrays(f)[1].mean(axis=0) for f in faces if len(f)]
            cal.accel = calibration.accel_six_position(np.array(means))
        except ValueError as e:
            cal.notes.append(f"accel: {e}")
        _, _, _, mag = raw_arrays(link.raw)
        try:
            cal.mag = calibration.mag_ellipsoid(mag)
        except ValueError as e:
            cal.notes.append(f"mag: {e}")
        block = _finish(args, cal, mag)
        if not (cal.gyro or cal.accel or cal.mag):
            print("sphere calibrate: nothing could be computed; nothing sent", file=sys.stderr)
            return 1
        reply = link.command(SetCalibration(**block))
        if reply is None or not reply.ok:
            print(f"sphere calibrate: the sphere did not accept SET_CALIBRATION ({reply})", file=sys.stderr)
            return 1
        print("sent to the sphere (in use now)", file=sys.stderr)
        if not args.no_save:
            reply = link.command(SaveCalibration(), timeout_s=2.0)
            if reply is None or not reply.ok:
                print(f"sphere calibrate: SAVE_CALIBRATION failed ({reply})", file=sys.stderr)
                return 1
            print("saved to EEPROM", file=sys.stderr)
        del turning
        return 0
    finally:
        port.close()
        if writer:
            writer.close()
