"""SET_BAUD on the virtual board (protocol/spec.md §5.4): switches up and down, and fall-backs, with every frame counted.

The real firmware on the virtual board in real time behind a USB adapter model, read the way sphere-mouse reads it
(``open_port`` with the low-latency request, ``DeviceLink``). The board garbles every byte whose two ends run at
different rates (hardware/sim/README.md, "Baud rates"), so a frame sent at a rate the host does not listen at is
lost, as on a real line. ``--rounds`` rounds, alternately:

- a **switch** up to ``--baud`` and back, each by the daemon's own procedure (``sphere.link.baud.switch_baud``):
  SET_BAUD, the port to the new rate, ECHO (the confirmation, sent again while unanswered), a stretch of stream,
  the same down to 115200, a stretch of stream;
- a **fall-back**: SET_BAUD to ``--baud`` that the host never confirms (it stays at 115200 and sends nothing): the
  sphere must come back to 115200 by itself within 2 s; the time to its next intact frame is measured.

Counted over the whole run, from the decoder: sequence gaps and frames lost in them, CRC and framing errors, bytes
skipped, and stale frames (a RAW_SAMPLE whose device time is not after the one before). The target: all zero.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from sphere import argtypes
from sphere.link.baud import SET_BAUD_REPLY_S, switch_baud
from sphere.link.device import DeviceLink
from sphere.link.port import open_port, request_low_latency
from sphere.protocol import PacketStream, SetBaud
from sphere.protocol.packets import DEFAULT_BAUD
from sphere.sim import trace as T
from sphere.sim.board import BoardUnavailable, board_command, firmware_elf, start_pty_board

HELP = "SET_BAUD on the virtual board: switches and fall-backs, lost and stale frames counted"
RATES = (250000, 500000, 1000000)


def add_arguments(p) -> None:
    p.add_argument("--rounds", type=argtypes.at_least_one, default=100,
                   help="rounds, alternately a switch up and back and a fall-back (default 100: 100 switches, 50 fall-backs)")
    p.add_argument("--baud", type=_rate, default=1000000, help="the faster rate (250000, 500000 or 1000000; default 1000000)")
    p.add_argument("--adapter", choices=("none", "ch340", "ftdi"), default="ftdi",
                   help="the USB adapter model between board and host (default ftdi, with the low-latency request)")
    p.add_argument("--json", metavar="OUT", type=argtypes.out_file, help="also write the figures as JSON")


def _rate(text: str) -> int:
    b = argtypes.baud(text)
    if b not in RATES:
        raise argparse.ArgumentTypeError(f"baud {b}: SET_BAUD takes {', '.join(map(str, RATES))} (exact on 16 MHz)")
    return b


class Counter:
    """RAW_SAMPLE device times, to find stale frames (not after the one before)."""

    def __init__(self):
        self.last_t = None
        self.stale = 0
        self.samples = 0

    def __call__(self, dp):
        if dp.packet.NAME == "RAW_SAMPLE":
            self.samples += 1
            if self.last_t is not None and dp.t_us <= self.last_t:
                self.stale += 1
            self.last_t = dp.t_us


def run(args) -> int:
    seconds = 20 + args.rounds * 2.0
    try:
        elf = firmware_elf()
    except (RuntimeError, OSError) as e:
        print(f"sphere bench baud-switch: {e}", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory(prefix="sphere-baud-") as tmp:
        trace = T.to_chips(T.still(seconds)).write(Path(tmp) / "still.bin")
        stats_path = Path(tmp) / "stats.json"
        cmd = board_command(elf, trace, seconds, pty=True, adapter=None if args.adapter == "none" else args.adapter,
                            stats=stats_path)
        try:
            board, pty = start_pty_board(cmd)
        except BoardUnavailable as e:
            print(f"sphere bench baud-switch: {e}", file=sys.stderr)
            return 1
        try:
            ser = open_port(pty, DEFAULT_BAUD, timeout_s=0.01, reset_on_open=False, low_latency=True)
            counter = Counter()
            link = DeviceLink(ser, PacketStream("device"), on_packet=counter)
            if link.hello(timeout_s=10.0) is None:
                print("sphere bench baud-switch: no HELLO from the virtual board", file=sys.stderr)
                return 1
            link.pump(0.5)
            start_stats = _snapshot(link)

            def port_to(baud):
                ser.baudrate = baud
                request_low_latency(ser)

            switches = failed = 0
            echoes = []  # ECHOs each confirmed switch took (more than one: the first arrived before the sphere's switch)
            fallbacks_s = []
            t0 = time.monotonic()
            for k in range(args.rounds):
                if k % 2 == 0:  # up and back, each confirmed
                    for baud in (args.baud, DEFAULT_BAUD):
                        done = switch_baud(link, baud, port_to)  # the daemon's own procedure
                        echoes.append(done.echoes)
                        if not done.ok:
                            failed += 1
                            print(f"round {k}: " + (f"no answer at {baud} ({done.echoes} ECHOs)" if done.echoes else
                                                    f"SET_BAUD {baud}: {done.why}"), file=sys.stderr)
                            link.pump(1.5)  # the sphere comes back to 115200 by itself
                            break
                        switches += 1
                        link.pump(0.3)
                else:  # never confirmed: the sphere must come back by itself
                    reply = link.command(SetBaud(args.baud), timeout_s=SET_BAUD_REPLY_S, retries=0)
                    if reply is None or not reply.ok:
                        failed += 1
                        continue
                    asked, last_t = time.monotonic(), counter.last_t
                    before = counter.samples
                    while counter.samples == before and time.monotonic() - asked < 10.0:
                        link.read()
                    # on the sphere's own clock: the gap in its samples (a loaded machine runs the board slower
                    # than the wall clock; the sphere's second is what its timeout counts)
                    fallbacks_s.append((counter.last_t - last_t) / 1e6 if counter.samples > before else 10.0)
                    link.pump(0.2)
            wall = time.monotonic() - t0
            end_stats = _snapshot(link)
            ser.close()
        finally:
            if board.poll() is None:
                board.terminate()
                try:
                    board.wait(10)
                except subprocess.TimeoutExpired:
                    board.kill()
        board_stats = json.loads(stats_path.read_text()) if stats_path.exists() else {}
    delta = {k: end_stats[k] - start_stats[k] for k in end_stats}
    result = {"rounds": args.rounds, "baud": args.baud, "adapter": args.adapter, "switches": switches,
              "failed": failed, "fallbacks": len(fallbacks_s),
              "fallback_s": {"max": max(fallbacks_s) if fallbacks_s else None,
                             "median": sorted(fallbacks_s)[len(fallbacks_s) // 2] if fallbacks_s else None},
              "frames_ok": delta["frames_ok"], "raw_samples": counter.samples, "seq_gaps": delta["seq_gaps"],
              "frames_lost": delta["frames_lost"], "crc_errors": delta["crc_errors"],
              "framing_errors": delta["framing_errors"], "bytes_skipped": delta["bytes_skipped"],
              "stale_frames": counter.stale, "wall_s": wall,
              "echoes_resent": sum(n - 1 for n in echoes if n > 1),
              "garbled_bytes_to_host": board_stats.get("garbled_bytes_to_host"),
              "garbled_bytes_to_device": board_stats.get("garbled_bytes_to_device")}
    ok = (not failed and not result["frames_lost"] and not result["seq_gaps"] and not result["crc_errors"]
          and not result["stale_frames"] and (not fallbacks_s or max(fallbacks_s) <= 2.0))
    result["pass"] = ok
    print(f"SET_BAUD {args.baud} on the virtual board ({args.adapter}): {switches} switches, {len(fallbacks_s)} "
          f"fall-backs ({failed} failed) in {wall:.0f} s")
    print(f"frames ok {result['frames_ok']}, seq gaps {result['seq_gaps']} ({result['frames_lost']} lost), "
          f"CRC errors {result['crc_errors']}, framing errors {result['framing_errors']}, bytes skipped "
          f"{result['bytes_skipped']}, stale frames {result['stale_frames']}; ECHOs sent again "
          f"{result['echoes_resent']}, garbled bytes to the sphere {result['garbled_bytes_to_device']}, to the host "
          f"{result['garbled_bytes_to_host']}")
    if fallbacks_s:
        print(f"never confirmed -> next sample at 115200 (the sphere's clock): median {result['fallback_s']['median']:.2f} s, "
              f"max {result['fallback_s']['max']:.2f} s (target <= 2 s)")
    print("PASS" if ok else "FAIL")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=2)
    return 0 if ok else 1


def _snapshot(link) -> dict:
    s = link.stream.stats
    return {k: getattr(s, k) for k in ("frames_ok", "seq_gaps", "frames_lost", "crc_errors", "framing_errors",
                                       "bytes_skipped")}
