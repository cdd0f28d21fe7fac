"""`sphere decode CAPTURE`: print the packets of a serial capture."""

from __future__ import annotations

import json
import sys

from sphere.link.capture import CaptureError, CaptureFile
from sphere.protocol.packets import BY_TYPE

HELP = "decode a serial capture and print its packets"
DESCRIPTION = (
    "Decode a serial capture (the raw bytes from the sphere's port) and print one line per packet. "
    "With --jsonl, one JSON object per packet on stdout and a JSON summary of the decoder's counters "
    "on stderr."
)


def add_arguments(p) -> None:
    p.add_argument("capture", help="capture file (raw bytes as received from the port)")
    p.add_argument("--jsonl", action="store_true", help="one JSON object per packet; summary as JSON on stderr")
    p.add_argument("--raw", action="store_true", help="print field values as on the wire instead of physical units")
    p.add_argument("--type", action="append", metavar="NAME", help="only packets of this type (repeatable), e.g. raw_sample")


def _text_line(obj: dict) -> str:
    head = f"{obj.pop('type'):<12} seq={obj.pop('seq'):<3}"
    if "t_us" in obj:
        head += f" t={obj.pop('t_us') / 1e6:10.6f}s"
    return head + " " + " ".join(f"{k}={v}" for k, v in obj.items())


def run(args) -> int:
    try:
        capture = CaptureFile(args.capture)
    except CaptureError as e:
        print(f"sphere decode: {e}", file=sys.stderr)
        return 2
    wanted = {t.lower() for t in args.type} if args.type else None
    known = {cls.NAME.lower() for cls in BY_TYPE.values() if cls.DIRECTION == "device"}  # what a capture holds
    if wanted and not wanted <= known:
        print(f"sphere decode: --type {', '.join(sorted(wanted - known))}: not a packet type the sphere sends; a "
              f"capture holds {', '.join(sorted(known))}", file=sys.stderr)
        return 2
    out = sys.stdout
    count = 0
    try:
        for item in capture.packets():
            obj = item.packet.to_json(raw=args.raw)
            if wanted and obj["type"] not in wanted:
                continue
            if item.t_us is not None:
                obj["t_us"] = item.t_us
            count += 1
            out.write((json.dumps(obj) if args.jsonl else _text_line(obj)) + "\n")
    except CaptureError as e:
        print(f"sphere decode: {e}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `sphere decode ... | head`
        return 0
    stats = capture.stats
    if stats.bytes_in == 0:  # what was read, so a FIFO or a pipe is judged by its contents, not its size
        print(f"sphere decode: {args.capture} is empty: nothing was received (is the sphere on, and the port right?)", file=sys.stderr)
        return 1
    cut = len(capture.decoder.pending())  # bytes after the last delimiter: a frame the recording stopped in
    summary = {"summary": True, "packets": count, **stats.as_dict(), "bytes_unfinished": cut}
    if args.jsonl:
        print(json.dumps(summary), file=sys.stderr)
    else:
        print(
            f"{stats.frames_ok} frames from {stats.bytes_in} bytes; errors: {stats.crc_errors} CRC, "
            f"{stats.framing_errors} framing, {stats.oversize} oversize, {stats.unknown_types} unknown type, "
            f"{stats.bad_lengths} bad length; {stats.bytes_skipped} bytes skipped; {stats.seq_gaps} sequence "
            f"gaps ({stats.frames_lost} frames lost); {stats.duplicates} duplicates dropped"
            + (f"; the last {cut} bytes are a frame the capture ends in the middle of" if cut else ""),
            file=sys.stderr,
        )
    if stats.frames_ok == 0:
        print(
            f"sphere decode: no valid frame in {stats.bytes_in} bytes of {args.capture}: this is not a sphere "
            "capture, or it was recorded at the wrong baud rate (the sphere sends 115200 8N1)",
            file=sys.stderr,
        )
        return 1
    return 0
