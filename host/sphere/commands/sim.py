"""`sphere sim`: run the real firmware on the virtual board (hardware/sim), fed by recorded or synthetic
motion, and report its timing, its stream and (with --accuracy) its orientation error."""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from sphere import argtypes
from sphere.argtypes import out_file, seconds_up_to
from sphere.broad import find_trial, load_trial, trial_paths
from sphere.progress import bar, follow_capture
from sphere.sim import trace as T
from sphere.sim.analysis import accuracy, accuracy_table, summarise
from sphere.sim.board import BoardUnavailable, board_path, firmware_elf, run_board, testfw_elf
from sphere.sim.soak import FAULT_KINDS, run_soak

HELP = "run the firmware on the simulated board (simavr) fed by a BROAD trial or a synthetic motion"
DESCRIPTION = (
    "Run the firmware image on a simulated ATmega328P at 16 MHz with register-level ADXL345, ITG-3200 "
    "and HMC5883L models fed by motion: a BROAD trial (a .mat path, a name or its number, e.g. 24), a "
    f"synthetic motion (synthetic:NAME[:ARG], NAME one of {', '.join(T.SYNTHETIC)}; e.g. synthetic:tour, "
    "synthetic:rotation:200 in °/s, synthetic:turn:45 in degrees) or a prepared trace (.bin). The UART goes "
    "into a capture file (--capture, readable by `sphere decode`) and/or a pseudo-terminal (--pty, for `sphere capture` or sphere-mouse). Prints the run's figures; "
    "--stats writes them as JSON. The I2C bus runs at its real 400 kHz timing (--simavr-i2c-timing: simavr's "
    "1 us per step); the MARG update's cycle counts (from the timing pin D13) are exact. The board can be "
    "one of several variants (--board), its chips noisy and on their own clocks (--noise, --clocks random), and "
    "faults can be injected (--nack, --stall, --glitch, --brownout, --power-off, --reset-mid-read, --sda-held, --host-stall). "
    "--soak SECONDS runs the firmware on BROAD motion under a random schedule of all faults and checks the "
    "stream's invariants (hardware/sim/README.md)."
)

DEFAULT_BETA = 0.041  # the firmware's DEFAULT_BETA_MILLI (firmware/src/core/marg_filter.h)


CHIPS = ("adxl345", "itg3200", "hmc5883l", "qmc5883l")


def _previous(text: str) -> tuple[str, float]:
    """FILE.elf:T: an ELF that exists and a time after 0."""
    path, sep, t = text.rpartition(":")
    try:
        t_s = float(t)
        if not sep or not path or not math.isfinite(t_s) or t_s <= 0:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give FILE.elf:T, T the seconds after power-up at which the "
                                         "firmware is flashed over it, e.g. sketch.elf:1.0") from None
    if not Path(path).is_file():
        raise argparse.ArgumentTypeError(f"{path}: no such file (the earlier sketch's ELF)")
    return path, t_s


def _span(text: str) -> str:
    """T0:T1 in seconds (T1 may be inf), checked here so a typo is one clear line, not a board error."""
    a, sep, b = text.partition(":")
    try:
        t0, t1 = float(a), float(b)
        if not sep or not (math.isfinite(t0) and 0 <= t0 < t1) or math.isnan(t1):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give T0:T1 in seconds with 0 <= T0 < T1, e.g. 3.0:3.5 "
                                         "(T1 may be inf)") from None
    return text


def _nack(text: str) -> str:
    """CHIP:T0:T1."""
    chip, sep, span = text.partition(":")
    if chip not in CHIPS or not sep:
        raise argparse.ArgumentTypeError(f"{text!r}: give CHIP:T0:T1 with CHIP one of {', '.join(CHIPS)}, "
                                         "e.g. itg3200:3:5")
    _span(span)
    return text


def _send_file(text: str) -> str:
    """A file of lines 'SECONDS HEX HEX ...' (checked before the board starts)."""
    path = argtypes.in_file(text)
    try:
        with open(path, encoding="utf-8") as f:
            for n, line in enumerate(f, 1):
                words = line.split()
                if not words or words[0].startswith("#"):
                    continue
                float(words[0])
                bytes(int(w, 16) for w in words[1:])
    except (ValueError, UnicodeDecodeError):
        raise argparse.ArgumentTypeError(f"{text!r} line {n}: expected 'SECONDS HEX HEX ...', e.g. '0.5 7E 01'") from None
    except OSError as e:
        raise argparse.ArgumentTypeError(f"{text!r}: cannot read: {e.strerror}") from None
    return path


MAX_SECONDS = 86400.0  # a simulated day: longer runs are a typo (1e9 s would need terabytes of trace)


#: how far --clock-ppm may put a chip's oscillator off: half its rate either way (the datasheets' tolerances are
#: 1-2 %, 10000-20000 ppm; -1e6 would stop its clock)
MAX_PPM = 500000.0

#: --glitch's limit: the firmware makes about 700 I2C transactions a second, so more faults than that only fill
#: the schedule (and at 1e99 a second the board's next-fault time, t + 1/RATE, stopped advancing: it hung)
MAX_GLITCH_RATE = 1000.0


def _chip_ppm(text: str) -> str:
    chip, sep, ppm = text.partition(":")
    try:
        if chip not in CHIPS or not sep or not abs(float(ppm)) <= MAX_PPM:  # (nan fails too)
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give CHIP:PPM with CHIP one of {', '.join(CHIPS)} and PPM from "
                                         f"{-MAX_PPM:g} to {MAX_PPM:g}, e.g. itg3200:20000") from None
    return text


def _start(text: str):
    """--start: 'auto' or the seconds into the trial (0 or more)."""
    if text == "auto":
        return text
    try:
        return argtypes.at_most(argtypes.non_negative, MAX_SECONDS, "seconds")(text)
    except argparse.ArgumentTypeError as e:
        raise argparse.ArgumentTypeError(f"{e} (or auto: 10 s before the trial's first movement)") from None


def add_arguments(p) -> None:
    p.add_argument("--trace", action="append", default=[], metavar="SOURCE",
                   help="BROAD trial (.mat, name or number), synthetic:NAME[:ARG], or a prepared .bin trace; "
                        "repeatable with --accuracy ('all' = every shipped trial)")
    p.add_argument("--seconds", type=seconds_up_to(MAX_SECONDS), default=None,
                   help="simulated seconds (default: 10; with --accuracy 60 per trial)")
    p.add_argument("--start", type=_start, default=None,
                   help="start this far into a BROAD trial (s), or 'auto': 10 s before its first movement "
                        "(default 0; with --accuracy auto)")
    p.add_argument("--full", action="store_true", help="play the whole BROAD trial (overrides --seconds and --start)")
    p.add_argument("--hold", type=argtypes.at_most(argtypes.non_negative, MAX_SECONDS, "seconds"), default=0.0,
                   help="lead-in: hold the first sample still for this long before the motion (s)")
    p.add_argument("--firmware", default=None,
                   help="firmware image (default firmware/build/sphere.elf, built with `make -C firmware`); "
                        "'testfw' = the board's own test sketch")
    p.add_argument("--capture", metavar="OUT", type=out_file, help="write the UART's byte stream here")
    p.add_argument("--pty", action="store_true", help="serve the UART on a pseudo-terminal (implies --realtime)")
    p.add_argument("--realtime", action="store_true", help="pace simulated time to the wall clock")
    p.add_argument("--stats", metavar="OUT.json", type=out_file, help="write the figures as JSON")
    p.add_argument("--nack", action="append", default=[], metavar="CHIP:T0:T1", type=_nack,
                   help="fault: CHIP (adxl345|itg3200|hmc5883l) stops answering from T0 to T1 s (T1 may be inf)")
    p.add_argument("--stall", action="append", default=[], metavar="T0:T1", type=_span,
                   help="fault: the I2C bus is stalled (clock held) from T0 to T1 s")
    p.add_argument("--send", metavar="FILE", type=_send_file, help="bytes for the device's UART, lines 'SECONDS HEX HEX ...'")
    p.add_argument("--timing-pin", default=None, help="pin high during the MARG update (default B5 = D13)")
    p.add_argument("--loop-pin", default=None, help="pin high during a whole period's work, if the firmware has one")
    p.add_argument("--rate", type=argtypes.positive, default=None, help="the firmware's sample rate in Hz (default 200)")
    p.add_argument("--i2c-real-timing", action="store_true",
                   help="(the default now) each I2C byte takes 9 SCL periods at the firmware's TWBR rate")
    p.add_argument("--simavr-i2c-timing", action="store_true",
                   help="simavr's own I2C timing (1 us per step), faster but not the real bus")
    p.add_argument("--board", default=None, choices=("aligned", "sen10724", "gy85", "gy85-qmc"),
                   help="board variant (default aligned): each chip's axes as mounted there; gy85-qmc has a QMC5883L")
    p.add_argument("--noise", action="store_true",
                   help="the chips' datasheet noise, turn-on offsets and gyro warm-up drift")
    p.add_argument("--seed", type=int, default=None, help="seed of the noise, the clocks and the faults (default 1)")
    p.add_argument("--clock-ppm", action="append", default=[], metavar="CHIP:PPM", type=_chip_ppm,
                   help="a chip's oscillator off the Nano's crystal by PPM")
    p.add_argument("--clocks", choices=["random"], default=None,
                   help="every chip's oscillator off by a seeded amount within its datasheet's tolerance")
    p.add_argument("--glitch", type=argtypes.at_most(argtypes.non_negative, MAX_GLITCH_RATE, "a second"), default=None,
                   metavar="RATE",
                   help="transient I2C faults, RATE a second on average: single NACKs, clock stretching, a reset "
                        "in the middle of a read (the chip then holds SDA low)")
    p.add_argument("--brownout", action="append", type=argtypes.non_negative, default=[], metavar="T",
                   help="the supply dips at T s: the AVR and the chips restart")
    p.add_argument("--power-off", action="append", type=argtypes.non_negative, default=[], metavar="T",
                   help="the supply is cut at T s and comes back: a power-on reset (RAM lost, the chips restart)")
    p.add_argument("--reset-mid-read", action="append", type=argtypes.non_negative, default=[], metavar="T",
                   help="reset the AVR at the first byte a chip sends after T s (the chip holds SDA)")
    p.add_argument("--sda-held", action="store_true", help="at power-up a sensor holds SDA low")
    p.add_argument("--host-stall", action="append", default=[], metavar="T0:T1", type=_span,
                   help="the host stops reading from T0 to T1 s (the adapter's buffer overflows)")
    p.add_argument("--adapter", choices=["ftdi", "ch340"], default=None,
                   help="a USB-serial adapter between the UART and the host: FTDI (62-byte packets, 16 ms latency "
                        "timer) or CH340 (each 1 ms USB frame); default none")
    p.add_argument("--bootloader", choices=("optiboot4", "atmegaboot", "optiboot8", "none"), default=None,
                   help="a boot loader in front of the firmware, as on a Nano: optiboot4 (Optiboot 4.4, the Nano's), "
                        "atmegaboot (the old Nano bootloader), optiboot8 (a current Optiboot) or none (the default)")
    p.add_argument("--hang", action="append", default=[], metavar="T0:T1", type=_span,
                   help="fault: the firmware's main program hangs from T0 to T1 s (interrupts and the watchdog go on)")
    p.add_argument("--previous", metavar="FILE.elf:T", type=_previous, default=None,
                   help="run an earlier sketch from power-up and flash the firmware over it at T s (the stick keeps "
                        "its power and the registers that sketch set)")
    p.add_argument("--bus-pullup", type=argtypes.positive, default=None, metavar="KOHM",
                   help="the sensor board's pull-ups on SDA and SCL to 3.3 V, for the bus's level check (default 4.7)")
    p.add_argument("--accuracy", action="store_true",
                   help="compare the firmware's quaternions with BROAD's optical reference and the host Madgwick")
    p.add_argument("--beta", type=argtypes.positive, default=DEFAULT_BETA, help="β of the host Madgwick (default the firmware's)")
    p.add_argument("--host-independent", action="store_true",
                   help="the host Madgwick decides alone (no tap/norm rejections, no start-up gain) instead of "
                        "following the firmware's flags")
    p.add_argument("--jobs", type=argtypes.at_least_one, default=2, help="boards run at once with several traces (default 2)")
    p.add_argument("--no-build", action="store_true", help="do not run make; fail with the command instead")
    p.add_argument("--json", nargs="?", const=True, default=None, metavar="OUT", type=out_file,
                   help="print the figures as JSON (with a file name: write them there; the soak's report)")
    p.add_argument("--soak", type=seconds_up_to(MAX_SECONDS), default=None, metavar="SECONDS",
                   help="soak run: the firmware on BROAD motion for SECONDS under a seeded schedule of every fault, "
                        "checked against a fault-free run of the same motion; exit 1 when an invariant fails")
    p.add_argument("--soak-faults", default=None, metavar="KIND,...",
                   help="only these fault kinds in the soak (default all: nack, stall, glitch, brownout, "
                        "reset_mid_read, sda_held, host_stall)")
    p.add_argument("-v", "--verbose", action="count", default=0, help="log the bus (twice: every byte)")


def prepare(source: str, seconds: float | None, start_s, hold_s: float, out: Path, full: bool = False):
    """Write the board's trace for SOURCE; returns (trace path, played seconds, BROAD trial slice or None)."""
    if source.endswith(".bin") and Path(source).exists():
        ct = T.ChipTrace.read(source)
        return Path(source), seconds or ct.seconds, None
    if source.startswith("synthetic:") or source in T.SYNTHETIC:
        spec = source.split(":", 1)[1] if source.startswith("synthetic:") else source
        secs = seconds or 10.0
        m = T.hold_first(T.synthetic(spec, max(secs - hold_s, 0.5)), hold_s)
        T.to_chips(m).write(out)
        return out, secs, None

    trial = load_trial(find_trial(source))
    total = len(trial) / trial.rate_hz
    if start_s in (None, ""):
        start_s = 0.0
    elif start_s == "auto":
        first = int(np.argmax(trial.movement)) / trial.rate_hz if trial.movement.any() else 0.0
        start_s = max(0.0, first - 10.0)
    else:
        start_s = float(start_s)
        if start_s >= total:
            raise ValueError(f"--start {start_s:g}: trial {trial.name} is only {total:.1f} s long; start within it")
    secs = seconds if seconds is not None else 10.0
    if full:
        start_s, secs = 0.0, hold_s + total
    play = min(max(secs - hold_s, 0.0), total - start_s)
    sl = trial.seconds(start_s, play)
    m = T.hold_first(T.from_broad(sl), hold_s)
    T.to_chips(m).write(out)
    return out, hold_s + len(sl) / sl.rate_hz, sl


def board_options(args) -> dict:
    """The board's variant, imperfections and faults from the command line (run_board's keywords)."""
    return dict(i2c_real_timing=not args.simavr_i2c_timing, board=args.board, noise=args.noise, seed=args.seed,
                clock_ppm=args.clock_ppm, clocks_random=args.clocks == "random", glitch=args.glitch,
                brownout=args.brownout, power_off=args.power_off, reset_mid_read=args.reset_mid_read, sda_held=args.sda_held,
                host_stall=args.host_stall, adapter=args.adapter, bootloader=args.bootloader, hang=args.hang,
                previous=args.previous, bus_pullup_kohm=args.bus_pullup)


def _one(args, source: str, elf, tmp: Path, index: int, multi: bool):
    seconds = args.seconds if args.seconds is not None else (60.0 if args.accuracy else None)
    start = args.start if args.start is not None else ("auto" if args.accuracy else 0.0)
    trace, secs, trial = prepare(source, seconds, start, args.hold, tmp / f"trace{index}.bin", args.full)
    capture = args.capture if (args.capture and not multi) else tmp / f"capture{index}.bin"
    # the board writes its figures to a file of ours; --stats is written here, from what this run adds
    stats_out = args.stats if (args.stats and not multi) else None

    with follow_capture(None if (multi or args.pty) else capture, secs, desc=f"sim {source}"):
        run = run_board(elf, trace, secs, capture, interactive=args.pty, pty=args.pty, realtime=args.realtime,
                        nack=args.nack, stall=args.stall, send=args.send,
                        timing_pin=args.timing_pin, loop_pin=args.loop_pin, rate_hz=args.rate,
                        verbose=args.verbose, build=not args.no_build, **board_options(args))
    # read back only a capture the board finished writing to a file (never /dev/full, a fifo, a short file)
    ok = run.returncode == 0 and Path(capture).is_file()
    summary = summarise(Path(capture)) if ok else None
    stats = dict(run.stats)
    if summary is not None:
        dev = summary.as_dict()
        stats["stream"] = dev
        if summary.status:
            stats["device_loop_overruns"] = summary.status[-1].loop_overruns
            # the firmware's own figure: the longest period's work in each second / the period (per mille)
            stats["device_cpu_load_max"] = max(x.cpu_load for x in summary.status) / 1000.0
    acc = None
    if args.accuracy and trial is not None and summary is not None:  # (run() lets only BROAD trials through)
        acc = accuracy(summary, trial, args.hold, args.beta, bias_s=min(args.hold, 2.0),
                       follow_firmware=not args.host_independent)
    if stats_out and run.stats:
        Path(stats_out).write_text(json.dumps(stats, indent=2) + "\n")
    return source, run, stats, acc


def _print_figures(source: str, stats: dict, out=None) -> None:
    out = out or sys.stdout  # looked up per call: a default bound at import outlives a replaced stdout

    def c3(k):
        d = stats.get(k) or {}
        return f"min {d.get('min')} / median {d.get('median')} / max {d.get('max')}"

    s = stats.get("stream") or {}
    dec = s.get("decoder") or {}
    print(f"sphere sim {source}: {stats.get('simulated_seconds', 0):.2f} simulated s in "
          f"{stats.get('wall_seconds', 0):.2f} wall s (x{stats.get('speed', 0):.2f})", file=out)
    print(f"  cycles per MARG update: {c3('cycles_per_update')} (limit 10000)", file=out)
    print(f"  cycles per loop:        {c3('cycles_per_loop')}  [{stats.get('cpu_load_basis', '')}]", file=out)
    load = stats.get("cpu_load")
    print(f"  cpu_load at {stats.get('sample_rate_hz', 200):g} Hz: {load if load is None else f'{load:.3f}'} "
          f"(max {stats.get('cpu_load_max')}); {stats.get('i2c_timing_note', '')}", file=out)
    if stats.get("device_cpu_load_max") is not None:
        print(f"  device's own cpu_load (STATUS, longest period per second): max {stats['device_cpu_load_max']:.3f}", file=out)
    print(f"  overruns {stats.get('overruns')} (timing pin), device loop_overruns {stats.get('device_loop_overruns')}; "
          f"frames {stats.get('frames_sent')}; I2C transactions {stats.get('i2c_transactions')}, errors {stats.get('i2c_errors')}",
          file=out)
    if s:
        print(f"  stream: raw {s.get('raw_samples')} at {s.get('raw_rate_hz') or 0:.2f} Hz, orientation "
              f"{s.get('orientations')} at {s.get('orientation_rate_hz') or 0:.2f} Hz, events {s.get('events')}, "
              f"CRC errors {dec.get('crc_errors')}, seq gaps {dec.get('seq_gaps')}, hellos {s.get('hellos')}", file=out)


def _soak(args, elf) -> int:
    kinds = FAULT_KINDS
    if args.soak_faults:
        kinds = tuple(k.strip() for k in args.soak_faults.split(",") if k.strip())
        bad = [k for k in kinds if k not in FAULT_KINDS]
        if bad:
            print(f"sphere sim: unknown fault kind {', '.join(bad)}; choose from {', '.join(FAULT_KINDS)}",
                  file=sys.stderr)
            return 2
    if args.soak < 10:
        print("sphere sim: --soak needs at least 10 simulated seconds (faults start at 6 s)", file=sys.stderr)
        return 2
    try:
        with tempfile.TemporaryDirectory(prefix="sphere-soak-elf-") as tmpd:
            snapshot = Path(tmpd) / Path(elf).name  # a rebuild of firmware/build meanwhile must not change it
            shutil.copyfile(elf, snapshot)
            res = run_soak(snapshot, args.soak, args.seed if args.seed is not None else 1, board=args.board,
                           kinds=kinds, build=not args.no_build)
    except (FileNotFoundError, RuntimeError) as e:
        print(f"sphere sim: {e}", file=sys.stderr)
        return 2
    if isinstance(args.json, str):
        Path(args.json).write_text(json.dumps(res.report, indent=2) + "\n")
    elif args.json:
        print(json.dumps(res.report))
    print(res.summary_line())
    return 0 if res.ok else 1


def run(args) -> int:
    if not args.trace and args.soak is None:
        print("sphere sim: give --trace SOURCE (or --soak SECONDS)", file=sys.stderr)
        return 2
    sources = list(args.trace)
    if "all" in sources:
        sources = [str(p) for p in trial_paths()]
    if len(sources) > 1 and not args.accuracy:
        print("sphere sim: several --trace only with --accuracy", file=sys.stderr)
        return 2
    not_broad = [s for s in sources if s.startswith("synthetic:") or s in T.SYNTHETIC or s.endswith(".bin")]
    if args.accuracy and not_broad:
        print(f"sphere sim: --accuracy compares with BROAD's optical reference, which {', '.join(not_broad)} has "
              "not: give BROAD trials (a .mat, a name or a number, or all)", file=sys.stderr)
        return 2
    try:
        if args.firmware == "testfw":
            elf = testfw_elf(build=not args.no_build)
        elif args.firmware:
            elf = Path(args.firmware)
            if not elf.is_file():
                print(f"sphere sim: no firmware image at {elf}", file=sys.stderr)
                return 2
            with open(elf, "rb") as f:
                if f.read(4) != b"\x7fELF":
                    print(f"sphere sim: {elf} is not an ELF image (the firmware build's firmware/build/sphere.elf)",
                          file=sys.stderr)
                    return 2
        else:
            elf = firmware_elf(build=not args.no_build)
        board_path(build=not args.no_build)
    except BoardUnavailable as e:
        print(f"sphere sim: {e}", file=sys.stderr)
        return 2
    if args.soak is not None:
        return _soak(args, elf)
    multi = len(sources) > 1
    with tempfile.TemporaryDirectory(prefix="sphere-sim-") as tmpd:
        tmp = Path(tmpd)
        # run a snapshot of the image: a rebuild of firmware/build meanwhile must not change or remove it
        snapshot = tmp / Path(elf).name
        shutil.copyfile(elf, snapshot)
        elf = snapshot
        try:
            if multi:
                with ThreadPoolExecutor(max(1, args.jobs)) as ex:
                    runs = ex.map(lambda ia: _one(args, ia[1], elf, tmp, ia[0], True), enumerate(sources))
                    results = list(bar(runs, total=len(sources), desc="sim", unit="trace"))
            else:
                results = [_one(args, sources[0], elf, tmp, 0, False)]
        except (FileNotFoundError, ValueError) as e:
            print(f"sphere sim: {e}", file=sys.stderr)
            return 2
    rc = 0
    rows = []
    for source, brun, stats, acc in results:
        if brun.returncode != 0:
            rc = brun.returncode
            print(f"sphere sim: the board exited with {brun.returncode}: {brun.stderr.strip()[-500:]}", file=sys.stderr)
            if not stats.get("simulated_seconds"):
                continue  # it never ran: no figures to show
        if isinstance(args.json, str):
            Path(args.json).write_text(json.dumps({"source": source, **stats}, indent=2) + "\n")
            _print_figures(source, stats)
        elif args.json:
            print(json.dumps({"source": source, **stats}))
        else:
            _print_figures(source, stats)
        if brun.returncode == 0 and stats.get("frames_sent") == 0 and args.firmware != "testfw":
            print(f"sphere sim: the firmware sent no frame in {stats.get('simulated_seconds', 0):g} simulated s: it "
                  "starts streaming about 0.25 s after power-up (later behind a boot loader); give a longer --seconds",
                  file=sys.stderr)
        if acc is not None:
            rows.append(acc)
    if rows:
        print()
        how = ("deciding alone" if args.host_independent else
               "following the firmware's tap/norm rejections and start-up gain, sample by sample")
        print(f"Orientation error, dataset metric (RMSE over movement samples; host Madgwick β = {args.beta:g}, {how}):")
        print(accuracy_table(rows))
    return rc
