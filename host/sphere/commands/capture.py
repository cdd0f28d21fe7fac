"""`sphere capture --port PORT --out FILE`: record the raw byte stream from the sphere; with ``--camera DEV``
a session (:mod:`sphere.link.session`): the bytes and a camera's frames on one host clock, for
`sphere-mouse --replay SESSION`."""

from __future__ import annotations

import sys
import time

import serial

from sphere.argtypes import seconds
from sphere.link.capture import SIDECAR_SUFFIX, CaptureError, CaptureWriter
from sphere.protocol import PacketStream
from sphere.link.port import DEFAULT_BAUD, PortError, open_port
from sphere.link.session import SessionError, SessionWriter

HELP = "record the sphere's serial stream into a capture file"
DESCRIPTION = (
    "Record the bytes from the sphere's serial port exactly as received. Each chunk is flushed to the "
    "file as it arrives, so Ctrl-C or an unplug loses nothing already received. With --camera DEV, --out is "
    "a session folder: the bytes with their arrival times and the camera's frames (lossless) with theirs, on "
    "one clock; `sphere-mouse --replay FOLDER` plays both in step (host/docs/camera.md, Sessions)."
)


def add_arguments(p) -> None:
    p.add_argument("--port", required=True, help="serial port, e.g. /dev/ttyUSB0, /dev/rfcomm0, /dev/pts/3")
    p.add_argument("--out", required=True, help="capture file to write (overwritten); with --camera a new folder")
    p.add_argument("--camera", metavar="INDEX|FILE", help="also record this webcam (0, 1 ...) or video file (played "
                   "at its frame rate) into a session folder --out")
    p.add_argument("--baud", type=int, default=DEFAULT_BAUD, help=f"baud rate (default {DEFAULT_BAUD})")
    p.add_argument("--seconds", type=seconds, help="stop after this long (default: until Ctrl-C or unplug)")
    p.add_argument("--times", action="store_true", help=f"also write host receive times to FILE{SIDECAR_SUFFIX}")
    p.add_argument("--quiet", action="store_true", help="no progress line")


def run(args) -> int:
    try:
        port = open_port(args.port, args.baud)
    except PortError as e:
        print(f"sphere capture: {e}", file=sys.stderr)
        return 2
    camera = None
    try:
        if args.camera is not None:
            out, camera = _session(args)
        else:
            out = CaptureWriter(args.out, with_times=args.times)
    except CaptureError as e:
        port.close()
        print(f"sphere capture: {e}", file=sys.stderr)
        return 2
    stream = PacketStream()  # only to show progress; the file gets every byte, good or bad
    start = time.monotonic()
    last_report = 0.0
    status = 0
    with port, out:
        try:
            while args.seconds is None or time.monotonic() - start < args.seconds:
                try:
                    data = port.read(max(1, port.in_waiting or 1))
                except (serial.SerialException, OSError, TypeError) as e:
                    print(f"\nsphere capture: the port went away ({e}); {out.bytes_written} bytes kept in {args.out}", file=sys.stderr)
                    status = 1
                    break
                if not data:
                    continue
                try:
                    out.write(data) if camera is None else out.write_serial(data)
                except CaptureError as e:
                    print(f"\nsphere capture: {e}", file=sys.stderr)
                    status = 1
                    break
                stream.feed(data)
                now = time.monotonic()
                if not args.quiet and now - last_report > 0.5:
                    last_report = now
                    s = stream.stats
                    print(f"\r{out.bytes_written} bytes, {s.frames_ok} frames, {s.errors} bad, {s.frames_lost} lost   ", end="", file=sys.stderr)
        except KeyboardInterrupt:
            pass
        finally:
            if camera is not None:
                camera.stop()  # before the session's files close
        video = ""
        if camera is not None:
            video = f", {out.frames} camera frames"
            if camera.error:
                print(f"\nsphere capture: the camera stopped: {camera.error}", file=sys.stderr)
                status = 1
        if not args.quiet:
            s = stream.stats
            print(f"\r{out.bytes_written} bytes, {s.frames_ok} frames, {s.errors} bad, {s.frames_lost} lost{video}: "
                  f"saved to {args.out}", file=sys.stderr)
    if status == 0 and out.bytes_written == 0:
        print(f"sphere capture: nothing arrived from {args.port} in {time.monotonic() - start:.1f} s: is the sphere "
              f"on, and this its port? ({args.out} is empty)", file=sys.stderr)
        status = 1
    elif status == 0 and stream.stats.frames_ok == 0:
        print(f"sphere capture: none of the {out.bytes_written} bytes from {args.port} was a sphere frame: another "
              f"device, or the wrong baud rate (the sphere sends {DEFAULT_BAUD} 8N1); they are kept in {args.out}",
              file=sys.stderr)
        status = 1
    return status


def _session(args):
    """(SessionWriter, the camera reading into it) for --camera; CaptureError when either cannot be used."""
    try:
        import cv2  # noqa: F401  (optional: OpenCV, the camera extra; camera.live needs it only once it opens)
        from sphere.camera.live import CameraError, CameraSource  # optional: the camera (OpenCV, the camera extra)
    except ImportError as e:
        raise CaptureError(f"--camera needs OpenCV ({e}); install the camera extra: pip install -e '.[camera]'") from None
    camera = CameraSource(args.camera, realtime=True, detect=False)
    try:
        camera.open()
    except CameraError as e:
        raise CaptureError(str(e)) from None
    try:
        out = SessionWriter(args.out, camera.camera.width, camera.camera.height, camera.fps, clock=camera.clock,
                            extra={"camera": str(args.camera)})
    except SessionError:
        camera.release()
        raise
    camera.on_frame = lambda image, t: out.write_frame(image, t - out.t0)
    camera.start()
    return out, camera
