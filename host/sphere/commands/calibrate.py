"""`sphere calibrate`: gyro bias, accelerometer six-position and magnetometer ellipsoid calibration."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from sphere import chips
from sphere.argtypes import baud, image_file, out_file, seconds
from sphere.calibration import axis_check
from sphere.calibration import session as session
from sphere.calibration.axis_check import TURN_DEG
from sphere.calibration.fit import plot_mag_cloud
from sphere.calibration.session import (
    COVERAGE_BINS,
    COVERAGE_TARGET,
    FACE_S,
    STILL_S,
    TURN_MIN_S,
    TURN_S,
    SeriesBuilder,
)
from sphere.calibration.session import FACES as _FACES
from sphere.daemon.sources.base import version_problem
from sphere.errors import LinkLost, SphereError
from sphere.link.capture import CaptureError, CaptureFile, CaptureWriter
from sphere.link.device import DeviceLink
from sphere.link.device_settings import RATES_HZ
from sphere.link.port import PortError, open_port
from sphere.protocol import CalibrationBlock, GetCalibration, GetHello, SaveCalibration, SetCalibration
from sphere.protocol.packets import (CALIBRATION_STATE_BITS, RAW_ACCEL_OK, RAW_GYRO_OK, RAW_MAG_OK, STREAM_RAW,
                                     bit_names)

FACES = tuple(f[0] for f in _FACES)
DEFAULT_TIMEOUT_S = 120.0
NO_DATA_S = 5.0  # a step stops when no RAW_SAMPLE arrives for this long
MISSING_S = 1.0  # ... or when a sensor has been missing (its RAW_SAMPLE *_ok bit clear) for this long
SENSORS = ((RAW_ACCEL_OK, "accelerometer"), (RAW_GYRO_OK, "gyroscope"), (RAW_MAG_OK, "magnetometer"))

HELP = "calibrate the sphere's sensors (guided on a port, or offline from a capture)"
DESCRIPTION = f"""\
Computes the calibration block (protocol spec §5.2) from raw samples: gyro bias from a still phase,
accelerometer offset and scale from six still poses (each face of the sphere up), magnetometer hard and
soft iron from an ellipsoid fit over readings taken while turning the sphere every way. Prints the
result with the fit residual and the field norm before and after.

--port PORT guides you through four steps, each waiting for what it asks for, judged from the
sphere's RAW_SAMPLE stream in the sphere's own time (so a slow link does not matter):
  1/4 gyro bias: put the sphere down and do not touch it; done once it has been still for {STILL_S:g} s.
  2/4 axis check: turn it back and forth about each of its marked axes in turn (x, then y, then z, a
      quarter turn each way, its centre kept in place); done once each axis has turned {TURN_DEG:g}° and the
      three sensors' maps are told apart. A turn about one body axis must show on the same axis in the
      gyroscope, accelerometer and magnetometer; if not, it says which chip is mounted how and which
      board profile to set (`sphere device --port PORT set board=NAME`), and stops: nothing is sent.
  3/4 accelerometer: lay it on each of its six faces, still, in any order; a face counts once it has
      lain still for {FACE_S:g} s with that axis up; the progress line shows the faces still missing.
  4/4 magnetometer: turn it slowly through every direction; done once the field directions cover
      {round(COVERAGE_TARGET * COVERAGE_BINS)} of {COVERAGE_BINS} direction bins (after at least {TURN_MIN_S:g} s), or after {TURN_S:g} s.
Without --yes you press Enter before each step. A step not done within --timeout seconds (default
{DEFAULT_TIMEOUT_S:g}) stops the session with what was not seen and what to do; nothing is sent then. Otherwise the
result goes to the sphere (SET_CALIBRATION), is saved (SAVE_CALIBRATION, unless --no-save) and read
back (GET_CALIBRATION) to check that the sphere holds it.

--capture FILE does the same offline from a capture recorded with `sphere capture` (lay the sphere
still on six faces, a few seconds each, and turn it through every direction for ~30 s), with the same
still and face detection, and the axis check when the capture turns about every axis; nothing is sent."""


def add_arguments(p) -> None:
    p.formatter_class = argparse.RawDescriptionHelpFormatter  # keep the step list as written
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--port", help="the sphere's serial port: guided calibration, result sent and saved")
    src.add_argument("--capture", metavar="FILE", help="a capture file (sphere capture): offline, nothing is sent")
    p.add_argument("--baud", type=baud, default=115200)
    p.add_argument("--json", metavar="OUT", type=out_file, help="write the result as JSON")
    p.add_argument("--plot", metavar="PNG", type=image_file, help="write the magnetometer cloud before/after as a PNG")
    p.add_argument("--save-capture", metavar="FILE", type=out_file,
                   help="with --port: also keep the session's bytes as a capture")
    p.add_argument("--no-save", action="store_true", help="with --port: apply on the device but do not save to EEPROM")
    p.add_argument("--yes", action="store_true", help="with --port: do not wait for Enter before each step")
    p.add_argument("--no-axis-check", action="store_true",
                   help="with --port: skip step 2/4 (a board no profile fits, or a sphere without marked axes)")
    p.add_argument("--timeout", type=seconds, default=DEFAULT_TIMEOUT_S, metavar="SECONDS",
                   help=f"with --port: give up a step not done within this many seconds (default {DEFAULT_TIMEOUT_S:g})")


def block_from(cal, base=None) -> dict:
    """The SET_CALIBRATION fields (integers, spec §5.2) for a :class:`sphere.calibration.fit.Calibration`;
    parts that could not be computed keep ``base`` (the sphere's current block, a dict of the same
    fields), or the defaults."""
    q14 = 16384

    def i16(v):
        return int(np.clip(np.rint(v), -32768, 32767))

    out = {"gyro_bias": (0, 0, 0), "accel_offset": (0, 0, 0), "accel_scale": (q14,) * 3, "mag_offset": (0, 0, 0),
           "mag_soft_iron": (q14, 0, 0, 0, q14, 0, 0, 0, q14)}
    if base:
        out.update({k: tuple(int(x) for x in v) for k, v in base.items() if k in out})
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
            cal.notes.append("mag: soft-iron matrix does not fit Q14 (|entry| ≥ 2); the previous one kept")
    return out


BLOCK_FIELDS = ("gyro_bias", "accel_offset", "accel_scale", "mag_offset", "mag_soft_iron")


def block_of(packet) -> dict:
    """The block's fields of a SetCalibration packet (e.g. a GET_CALIBRATION reply's data, unpacked)."""
    return {k: tuple(int(x) for x in getattr(packet, k)) for k in BLOCK_FIELDS}


def report(cal, block) -> str:
    lines = []
    if cal.gyro is not None:
        g = cal.gyro
        lines.append(f"gyro bias: {np.round(g.bias_lsb, 1).tolist()} LSB = {np.round(g.bias_lsb / chips.ITG3200_LSB_PER_DPS, 3).tolist()} °/s "
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
                     f"{m.norm_after[1]:.0f} LSB ({m.radius_lsb / chips.HMC5883L_LSB_PER_UT:.1f} µT)")
    for n in cal.notes:
        lines.append(f"note: {n}")
    lines.append("SET_CALIBRATION block: " + json.dumps({k: list(v) for k, v in block.items()}))
    return "\n".join(lines)


def _write(args, path: str, write) -> None:
    """``write(path)``; a file that cannot be written is one line and loses nothing (the result is printed, and a
    session goes on to send it); the command's status is then 1."""
    try:
        write(path)
    except OSError as e:
        args.output_failed = f"cannot write {path}: {e.strerror or e}"
        print(f"sphere calibrate: {args.output_failed}; the result is printed above", file=sys.stderr)
        return
    print(f"wrote {path}", file=sys.stderr)


def _finish(args, cal, mag, base=None) -> dict:
    block = block_from(cal, base)
    print(report(cal, block))
    if args.json:
        _write(args, args.json, lambda path: Path(path).write_text(json.dumps(
            {"calibration": cal.as_dict(), "block": {k: list(v) for k, v in block.items()}}, indent=2)))
    if args.plot and cal.mag is not None:
        _write(args, args.plot, lambda path: plot_mag_cloud(mag, cal.mag, path))
    return block


def run(args) -> int:
    args.output_failed = None  # (--plot's image name and matplotlib are checked as the flags are read)
    code = _run_capture(args) if args.capture else _run_port(args)
    return 1 if code == 0 and args.output_failed else code


def _run_capture(args) -> int:
    try:
        cap = CaptureFile(args.capture)
        s = session.series_from_packets(cap.packets())
    except CaptureError as e:
        print(f"sphere calibrate: {e}", file=sys.stderr)
        return 2
    if len(s) < 50:
        print(f"sphere calibrate: {args.capture} holds {len(s)} raw samples; record raw samples with "
              "`sphere capture` while following the steps in `sphere calibrate --help`", file=sys.stderr)
        return 2
    rate = 1.0 / float(np.median(np.diff(s.t))) if len(s) > 1 else 200.0
    print(f"{len(s)} raw samples at {rate:.0f} Hz, {len(s.mag)} fresh magnetometer samples", file=sys.stderr)
    cal, faces = session.from_series(s)
    seen = [FACES[k] for k in sorted(faces)]
    print(f"faces seen still for {FACE_S:g} s: {', '.join(seen) or 'none'}", file=sys.stderr)
    _capture_axis_check(s, cap)
    _finish(args, cal, s.mag)
    return 0 if (cal.gyro or cal.accel or cal.mag) else 1


def _capture_axis_check(s, cap) -> None:
    """The axis check on a whole capture (said, never fatal: nothing is sent offline)."""
    hellos = [p for p in (getattr(d, "packet", d) for d in cap.packets()) if p.NAME == "HELLO"]
    profile = axis_check.profile_name(hellos[-1].board_profile if hellos else None)  # the newest: in use
    f = axis_check.fit(s)
    if not f.done:
        print("axis check: not made (the capture does not turn about every axis on its own, "
              f"{TURN_DEG:g}° each, or the sensors' maps are not told apart)", file=sys.stderr)
        return
    for line in axis_check.verdict(f, profile).lines:
        print(line, file=sys.stderr)


class _Link:
    """The session's link: commands and replies through :class:`sphere.link.device.DeviceLink`, and the
    RAW_SAMPLE values kept as they arrive (device time unwrapped by its PacketStream), for the steps to judge."""

    def __init__(self, port, writer=None):
        self.values = SeriesBuilder()
        self.last_raw_wall = time.monotonic()
        self.port_name = getattr(port, "port", None) or "PORT"
        self.missing_since: dict[str, float] = {}  # sensor → wall time since when the RAW_SAMPLEs say it is missing
        self.changed = ""  # what the session has changed on the sphere so far ("": nothing)
        self.device = DeviceLink(port, on_bytes=writer.write if writer else None, on_packet=self._packet)

    def _packet(self, dp):
        if dp.packet.NAME == "RAW_SAMPLE":
            self.last_raw_wall = now = time.monotonic()
            for bit, name in SENSORS:
                if dp.packet.flags & bit:
                    self.missing_since.pop(name, None)
                else:
                    self.missing_since.setdefault(name, now)
            self.values.add(dp.packet, dp.t_us * 1e-6)

    def missing(self, for_s: float = 0.0) -> list[str]:
        """The sensors the sphere's RAW_SAMPLEs have said missing for at least ``for_s`` seconds."""
        now = time.monotonic()
        return [name for _, name in SENSORS if now - self.missing_since.get(name, now) >= for_s
                and name in self.missing_since]

    @property
    def hello(self):
        return self.device.stream.hello

    def pump(self, seconds: float):
        return self.device.pump(seconds)

    def series(self, since: float | None = None):
        """The RAW_SAMPLE values so far (from device time ``since`` on)."""
        return self.values.series(since)

    def flush(self):
        """Drop what arrived while nobody was reading (a person reading the prompt)."""
        self.device.flush_input()

    def command(self, packet, timeout_s: float = 1.0):
        return self.device.command(packet, timeout_s)


class _Progress:
    """One progress line on stderr: rewritten in place on a terminal, else printed when it changes
    (at most once every 2 s unless its key changes)."""

    def __init__(self):
        self.tty = sys.stderr.isatty()
        self.key = None
        self.last = 0.0
        self.width = 0

    def show(self, text: str, key=None):
        now = time.monotonic()
        if self.tty:
            if now - self.last >= 0.1:
                print("\r" + text.ljust(self.width), end="", file=sys.stderr, flush=True)
                self.width, self.last = len(text), now
        elif key != self.key or now - self.last >= 2.0:
            print("  " + text, file=sys.stderr, flush=True)
            self.key, self.last = key, now

    def done(self, text: str):
        if self.tty:
            print("\r" + text.ljust(self.width), file=sys.stderr, flush=True)
        else:
            print("  " + text, file=sys.stderr, flush=True)
        self.key, self.width, self.last = None, 0, 0.0


class _StepFailed(SphereError):
    """A step that did not get what it asked for; the message says what was missing and what to do."""


def _bar(frac: float, n: int = 20) -> str:
    k = int(round(n * min(max(frac, 0.0), 1.0)))
    return "[" + "#" * k + " " * (n - k) + "]"


def _follow(link, timeout_s: float, poll, on_timeout):
    """Read the stream until ``poll(series_of_this_step)`` returns a result that is not None; a
    ``_StepFailed`` with ``on_timeout(series)`` after ``timeout_s`` of wall time (or when nothing arrives)."""
    t_wall = time.monotonic()
    link.pump(0.05)
    t0 = link.values.t[-1] if link.values.t else None
    while True:
        link.pump(0.1)
        if t0 is None and link.values.t:
            t0 = link.values.t[-1]
        s = link.series(t0) if t0 is not None else None
        if s is not None and len(s) > 1:
            r = poll(s)
            if r is not None:
                return r
        now = time.monotonic()
        gone = link.missing(MISSING_S)
        if gone:
            raise _StepFailed(_missing_text(gone, link.port_name) + "Nothing was sent.")
        if now - link.last_raw_wall > NO_DATA_S:
            raise _StepFailed(f"no RAW_SAMPLE from the sphere for {NO_DATA_S:g} s: is it still connected (and the "
                              "raw stream on, SET_STREAM bit 0)? Nothing was sent.")
        if now - t_wall > timeout_s:
            raise _StepFailed(on_timeout(s if s is not None else link.series(float("inf"))))


def _step_gyro(link, progress, timeout_s):
    def poll(s):
        span = session.trailing_still(s)
        still = span.seconds if span else 0.0
        if span is not None and still >= STILL_S - 1e-9:
            progress.done(f"still {_bar(1)} {STILL_S:.1f}/{STILL_S:g} s")
            return span
        progress.show(f"still {_bar(still / STILL_S)} {still:.1f}/{STILL_S:g} s" + ("" if still else "  (moving)"),
                      key=still > 0)
        return None

    def on_timeout(s):
        spans = session.still_spans(s)
        best = max((sp.seconds for sp in spans), default=0.0)
        return (f"step 1/4 (gyro bias) timed out after {timeout_s:g} s: the sphere was never still for {STILL_S:g} s "
                f"(longest still {best:.2f} s in {s.duration:.0f} s of samples). Put it down on a table, do not touch "
                "it, and run `sphere calibrate` again. Nothing was sent.")

    span = _follow(link, timeout_s, poll, on_timeout)
    s = link.series()
    sel = (s.t >= span.t0) & (s.t < span.t1)  # the span's samples, by device time
    return s.gyro[sel]


def _step_axes(link, progress, timeout_s, bias, port):
    """Step 2/4: the sphere turned about each of its axes; the three sensors must agree (sphere.calibration.axis_check)."""
    state = {"fit": None, "wall": 0.0}

    def poll(s):
        now = time.monotonic()
        turned = axis_check.turned_deg(s.t, s.gyro, bias)
        ticks = "  ".join(f"{'xyz'[i]} {'✓' if d >= TURN_DEG else f'{d:3.0f}°'}" for i, d in enumerate(turned))
        if all(turned >= TURN_DEG) and now - state["wall"] >= 1.0:  # the fit takes a while: once a second
            state["wall"] = now
            state["fit"] = axis_check.fit(s, bias)
            if state["fit"].done:
                progress.done(f"turned about  {ticks}")
                return state["fit"]
        doing = "comparing the three sensors (keep turning)" if all(turned >= TURN_DEG) else "keep turning"
        progress.show(f"turned about  {ticks}   {doing}", key=tuple(turned >= TURN_DEG))
        return None

    def on_timeout(s):
        turned = axis_check.turned_deg(s.t, s.gyro, bias)
        missing = [("xyz"[i]) for i, d in enumerate(turned) if d < TURN_DEG]
        if missing:
            what = (f"the gyroscope saw too little turning about {', '.join(missing)} on its own ("
                    + ", ".join(f"{'xyz'[i]} {d:.0f}°" for i, d in enumerate(turned)) + f"; {TURN_DEG:g}° each needed). "
                    "Turn the sphere back and forth about each marked axis in turn, a quarter turn each way")
        else:
            f = state["fit"] or axis_check.fit(s, bias)
            share = max(f.gyro.unexplained if f.gyro else 1.0, f.mag.unexplained if f.mag else 1.0)
            what = (f"the sensors' axes could not be told apart ({100 * share:.0f} % of the accelerometer's or "
                    "magnetometer's change unexplained). Turn the sphere in your hands about its centre, without "
                    "swinging or shaking it, away from magnets and iron")
        return (f"step 2/4 (axis check) timed out after {timeout_s:g} s: {what}; run `sphere calibrate` again "
                "(--no-axis-check skips this step). Nothing was sent.")

    f = _follow(link, timeout_s, poll, on_timeout)
    hello = link.device.hello(timeout_s=2.0, ask_after_s=0.2) or link.hello  # the profile in use now
    v = axis_check.verdict(f, axis_check.profile_name(getattr(hello, "board_profile", None)), port)
    for line in v.lines:
        print(("  " if v.ok else "") + line, file=sys.stderr)
    if not v.ok:
        raise _StepFailed("the board profile does not fit this board (above). Nothing was sent.")
    return v


def _step_faces(link, progress, timeout_s):
    state = {"seen": {}}

    def line(now):
        ticks = "  ".join(f"{name.split()[0]} {'✓' if i in state['seen'] else '·'}" for i, name in enumerate(FACES))
        if now.still_s <= 0:
            doing = "moving"
        elif now.face is None:
            doing = f"still {now.still_s:.1f} s, but no axis is up (lay it flat on a face)"
        elif now.face in state["seen"] and now.still_s >= FACE_S:
            doing = f"{FACES[now.face]} seen"
        else:
            doing = f"{FACES[now.face]}: still {now.still_s:.1f}/{FACE_S:g} s"
        return f"{ticks}   {doing}"

    def poll(s):
        before = set(state["seen"])
        state["seen"], now = session.update_faces(state["seen"], s)
        new = set(state["seen"]) - before
        for k in sorted(new):
            missing = session.missing_faces(state["seen"])
            progress.done(f"{FACES[k]} seen ({len(state['seen'])}/6)"
                          + (f"; still missing: {', '.join(missing)}" if missing else ""))
        if len(state["seen"]) == 6:
            return state["seen"]
        progress.show(line(now), key=(now.face, now.still_s > 0))
        return None

    def on_timeout(s):
        missing = session.missing_faces(state["seen"])
        seen = [FACES[k] for k in sorted(state["seen"])]
        return (f"step 3/4 (accelerometer) timed out after {timeout_s:g} s: faces not seen: {', '.join(missing)} "
                f"(seen: {', '.join(seen) or 'none'}). Lay the sphere on each missing face (that side up) and leave it "
                f"still for {FACE_S:g} s, then the next; run `sphere calibrate` again. Nothing was sent.")

    return _follow(link, timeout_s, poll, on_timeout)


def _step_turn(link, progress, timeout_s):
    need = int(round(COVERAGE_TARGET * COVERAGE_BINS))

    def poll(s):
        st = session.turn_status(s)
        c = st.coverage
        text = (f"turning {_bar(c.fraction / COVERAGE_TARGET)} directions {c.bins_hit}/{COVERAGE_BINS} (need {need}), "
                f"{st.seconds:4.1f} s (at least {TURN_MIN_S:g}, at most {TURN_S:g})")
        if st.done:
            progress.done(text)
            if st.reason == "time":
                print(f"  only {c.bins_hit} of {COVERAGE_BINS} directions after {TURN_S:g} s: the fit below may be poor",
                      file=sys.stderr)
            return st
        progress.show(text, key=c.bins_hit // 4)
        return None

    def on_timeout(s):
        st = session.turn_status(s)
        return (f"step 4/4 (magnetometer) timed out after {timeout_s:g} s: {st.seconds:.1f} s of samples arrived, "
                f"field directions covered {st.coverage.bins_hit} of {COVERAGE_BINS} (needs {need}, or {TURN_S:g} s of "
                "samples). Keep turning the sphere slowly through every direction — figure eights about every "
                "axis — and run `sphere calibrate` again. Nothing was sent.")

    return _follow(link, timeout_s, poll, on_timeout)


def _run_port(args) -> int:
    try:
        port = open_port(args.port, args.baud)
    except PortError as e:
        print(f"sphere calibrate: {e}", file=sys.stderr)
        return 2
    writer = None
    if args.save_capture:
        try:
            writer = CaptureWriter(args.save_capture)
        except CaptureError as e:
            port.close()
            print(f"sphere calibrate: {e}", file=sys.stderr)
            return 2
    link = _Link(port, writer)
    try:
        return _session(args, link)
    except KeyboardInterrupt:  # Ctrl-C, at a prompt or in a step
        print(f"\nsphere calibrate: interrupted; {link.changed or 'nothing was changed: the sphere keeps its calibration'}",
              file=sys.stderr)
        return 130
    except LinkLost as e:
        print(f"\nsphere calibrate: {e}; nothing more was sent", file=sys.stderr)
        return 1
    except CaptureError as e:
        print(f"\nsphere calibrate: {e}", file=sys.stderr)
        return 1
    finally:
        try:
            port.close()
        except Exception:
            pass
        if writer:
            try:
                writer.close()
            except CaptureError:
                pass


def _missing_text(names: list[str], port: str) -> str:
    return (f"the sphere's {' and '.join(names)} {'is' if len(names) == 1 else 'are'} not answering (its RAW_SAMPLEs "
            f"say so; `sphere device --port {port} get` lists the sensors found): check the wiring and the sensor "
            "board's power (hardware/README.md), then run `sphere calibrate` again. ")


def _stream_problem(hello, port: str) -> str | None:
    """Why the sphere's RAW_SAMPLE stream (as its HELLO says) cannot carry the steps, with the command that
    sets it, or None."""
    fix = (f"set it with `sphere device --port {port} set stream.raw=on stream.raw_rate_hz=200`, then run "
           "`sphere calibrate` again; nothing was sent")
    if hello is None:
        return f"no RAW_SAMPLE from the sphere (is its raw stream off?): {fix}"
    if not hello.stream_mode & STREAM_RAW:
        return f"the sphere's RAW_SAMPLE stream is off (stream.raw = off), and the steps are judged from it: {fix}"
    if hello.raw_rate_hz < session.MIN_RAW_RATE_HZ:
        slowest = min(r for r in RATES_HZ if r >= session.MIN_RAW_RATE_HZ)
        return (f"the sphere sends RAW_SAMPLE at {hello.raw_rate_hz} Hz, too few to tell whether it lies still "
                f"(the steps need {slowest} Hz or more; 200 Hz, the default, is best): {fix}")
    return None


def _session(args, link) -> int:
    """The guided steps on an open link (``_run_port`` opens and closes it)."""
    progress = _Progress()

    def wait(msg):
        if args.yes:
            print(msg, file=sys.stderr)
            return
        input(msg + " — press Enter ")
        link.flush()

    link.pump(0.6)
    if link.hello is None:
        link.command(GetHello())
        link.pump(0.3)
    if link.hello is not None:
        problem = version_problem(link.hello)
        if problem:
            print(f"sphere calibrate: {problem}", file=sys.stderr)
            return 1
    problem = _stream_problem(link.hello, args.port) if link.hello is not None else None
    if problem is None and link.missing(0.3):  # each step needs all three sensors (the steps check again)
        problem = _missing_text(link.missing(0.3), args.port) + "Nothing was sent."
    if problem is None and not link.values.t:
        link.pump(1.0)
        if not link.values.t:
            problem = _stream_problem(None, args.port)
    if problem:
        print(f"sphere calibrate: {problem}", file=sys.stderr)
        return 1
    reply = link.command(GetCalibration())
    base = block_of(CalibrationBlock.unpack(reply.data[:CalibrationBlock.SIZE])) if (
        reply is not None and reply.ok and len(reply.data) >= CalibrationBlock.SIZE) else None
    try:
        print(f"1/4 gyro bias: put the sphere down and do not touch it (still for {STILL_S:g} s).", file=sys.stderr)
        wait("   ready?")
        gyro_still = _step_gyro(link, progress, args.timeout)
        if args.no_axis_check:
            print("2/4 axis check: skipped (--no-axis-check)", file=sys.stderr)
        else:
            print("2/4 axis check: hold the sphere and turn it back and forth about each of its marked axes in "
                  "turn — about x, then y, then z — a quarter turn each way, keeping its centre in place.",
                  file=sys.stderr)
            wait("   ready?")
            bias = gyro_still.mean(axis=0) if len(gyro_still) else None
            _step_axes(link, progress, args.timeout, bias, args.port)
        print(f"3/4 accelerometer: lay the sphere on each of its six faces, still for {FACE_S:g} s each, in any "
              "order.", file=sys.stderr)
        wait("   ready?")
        faces = _step_faces(link, progress, args.timeout)
        print("4/4 magnetometer: turn the sphere slowly through every direction (figure eights, all axes).",
              file=sys.stderr)
        wait("   ready?")
        _step_turn(link, progress, args.timeout)
    except _StepFailed as e:
        progress.done("")
        print(f"sphere calibrate: {e}", file=sys.stderr)
        return 1
    except EOFError:
        print("\nsphere calibrate: no answer on the terminal (use --yes to run without Enter); nothing was sent",
              file=sys.stderr)
        return 1
    mag = link.series().mag
    cal = session.calibrate(gyro_still, {k: v.mean for k, v in faces.items()}, mag)
    block = _finish(args, cal, mag, base)
    if not (cal.gyro or cal.accel or cal.mag):
        print("sphere calibrate: nothing could be computed; nothing sent", file=sys.stderr)
        return 1
    if base is not None and not (cal.gyro and cal.accel and cal.mag):
        print("the parts not computed keep the sphere's current values", file=sys.stderr)
    reply = link.command(SetCalibration(**block))
    if reply is None or not reply.ok:
        print(f"sphere calibrate: the sphere did not accept SET_CALIBRATION ({reply})", file=sys.stderr)
        return 1
    print("sent to the sphere (in use now)", file=sys.stderr)
    link.changed = "the new calibration is in use on the sphere, not saved (--no-save)"
    if not args.no_save:
        link.changed = "the new calibration is in use on the sphere, perhaps not saved (run `sphere calibrate` again)"
        reply = link.command(SaveCalibration(), timeout_s=2.0)
        if reply is None or not reply.ok:
            print(f"sphere calibrate: SAVE_CALIBRATION failed ({reply})", file=sys.stderr)
            return 1
        print("saved to EEPROM", file=sys.stderr)
        link.changed = "the new calibration was sent and saved, but not read back"
    reply = link.command(GetCalibration())
    if reply is None or not reply.ok or len(reply.data) < CalibrationBlock.SIZE + 1:
        print(f"sphere calibrate: GET_CALIBRATION did not answer ({reply})", file=sys.stderr)
        return 1
    held = block_of(CalibrationBlock.unpack(reply.data[:CalibrationBlock.SIZE]))
    state = reply.data[CalibrationBlock.SIZE]
    if held != block:
        print(f"sphere calibrate: the sphere holds a different block: {held}", file=sys.stderr)
        return 1
    print(f"read back: the sphere holds it (calibration_state {', '.join(bit_names(state, CALIBRATION_STATE_BITS))})",
          file=sys.stderr)
    return 0
