"""Command-line flags of sphere-mouse, and putting the daemon together from them and the config file."""

from __future__ import annotations

import argparse
import atexit
import logging
import os
import signal
import sys
import time

from serial.tools import list_ports

from sphere import __version__
from sphere.camera.daemon_source import CameraPosition, CameraUnavailable
from sphere.daemon import config as config_mod
from sphere.daemon import sources
from sphere.daemon.backends import REGISTRY as BACKENDS
from sphere.daemon.app import SphereMouse
from sphere.daemon.backends import BackendUnavailable, open_backend
from sphere.daemon.backends.base import BackendLost
from sphere.daemon.config import ConfigError
from sphere.daemon.outputs.fanout import attach
from sphere.daemon.move_log import MoveLog, MoveLogError
from sphere.daemon.print_config import defaults_toml
from sphere.daemon.sources.base import SourceError, SourceFailed
from sphere.daemon.status import StatusLine, run_stats
from sphere.errors import output_failed

DESCRIPTION = """Turn the MARG sphere into a pointer (and a 3-D controller). Small wrist rotations move the
pointer; a tap clicks; a toss and catch switches mode (pointer → tilt → 3d). Settings come from
~/.config/sphere-mouse/config.toml (see host/docs/sphere-mouse.md); flags override them."""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="sphere-mouse", description=DESCRIPTION)
    src = p.add_argument_group("source (default: find the sphere on a serial port)")
    g = src.add_mutually_exclusive_group()
    g.add_argument("--port", help="serial port (/dev/ttyUSB0, /dev/rfcomm0) or 'auto' (discovery by HELLO)")
    g.add_argument("--replay", metavar="FILE", help="replay a capture file; exits when it ends")
    g.add_argument("--simulate", action="store_true", help="use the simulated sphere (the virtual board if "
                   "installed, else a built-in scripted sphere)")
    g.add_argument("--hid", action="store_true", help="read frames from a HID receiver (hidapi)")
    src.add_argument("--speed", type=float, help="replay speed: 1 = as recorded (default), 0 = as fast as possible")
    src.add_argument("--trace", help="motion the simulated sphere plays (--simulate): a BROAD trial (.mat, name or "
                     "number) or synthetic:NAME (default synthetic:tour)")
    src.add_argument("--baud", type=int, help="serial baud rate (default 115200)")
    src.add_argument("--camera", metavar="INDEX|FILE", help="a webcam (0, 1 ...) or a video file that sees the ball: "
                     "its position joins the 3-D stream and the outputs ([camera] section; needs the camera extra)")
    out = p.add_argument_group("output")
    out.add_argument("--backend", choices=("auto", *BACKENDS),
                     help="where pointer motion goes (default auto)")
    out.add_argument("--display", help="X display for --backend x11")
    out.add_argument("--mode", choices=config_mod.MODES, help="mode at start (default pointer)")
    out.add_argument("--sensitivity", type=float, metavar="DEG",
                     help="degrees of rotation per screen width (sets slow and fast: no acceleration)")
    out.add_argument("--no-stream", action="store_true", help="do not serve the WebSocket / 3-D page")
    out.add_argument("--stream-port", type=int, help="port of the WebSocket and the 3-D page (default 8765)")
    p.add_argument("--config", metavar="FILE", help="config file (default ~/.config/sphere-mouse/config.toml)")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override one config key, e.g. --set pointer.axes=local (repeatable)")
    p.add_argument("--status", action="store_true", help="print the status line every second even when "
                   "stderr is not a terminal")
    p.add_argument("--quiet", action="store_true", help="no status line")
    p.add_argument("--print-stats", action="store_true", help="when the daemon stops, print the run's figures on "
                   "stdout: frames, errors, losses, each sample's age on arrival (median, p95, p99, max), pointer moves")
    p.add_argument("--move-log", metavar="FILE", help="write each pointer move's times to FILE, a line each: when the "
                   "read that brought its sample returned and when the backend's move call returned (CLOCK_MONOTONIC "
                   "ns; sphere bench latency splits the host's part of the latency with it)")
    p.add_argument("-v", "--verbose", action="store_true", help="also log details: e.g. a serial driver that "
                   "offers no low-latency mode")
    p.add_argument("--check-config", action="store_true", help="validate the config and exit")
    p.add_argument("--print-config", action="store_true",
                   help="print every setting with its default and meaning (a config file to start from) and exit")
    p.add_argument("--udev-rule", metavar="PORT", help="print the udev rule that gives /dev/sphere and seat access "
                   "to the sphere on PORT only (its USB IDs and serial number), then exit")
    p.add_argument("--version", action="version", version=f"sphere-mouse {__version__}")
    return p


FTDI_VID = 0x0403


def udev_rule(port: str, comports=None) -> str:
    """The host/packaging/70-sphere-mouse.rules line for the USB-serial adapter on ``port``: its VID:PID and its
    serial number, or, for an adapter without one (CH340), the USB socket it is plugged into; for an FTDI
    adapter a second line that sets its latency timer to 1 ms."""
    if comports is None:
        comports = list_ports.comports
    real = os.path.realpath(port)
    for info in comports():
        if os.path.realpath(info.device) != real:
            continue
        if info.vid is None:
            break
        ident = (f'ATTRS{{serial}}=="{info.serial_number}"' if info.serial_number
                 else f'KERNELS=="{info.location}"')
        ids = f'ATTRS{{idVendor}}=="{info.vid:04x}", ATTRS{{idProduct}}=="{info.pid:04x}", {ident}'
        rule = f'SUBSYSTEM=="tty", {ids}, SYMLINK+="sphere", MODE="0660", TAG+="uaccess"'
        if info.vid == FTDI_VID:  # its latency timer to 1 ms (the rules file says why)
            rule += f'\nACTION=="add", SUBSYSTEM=="usb-serial", DRIVER=="ftdi_sio", {ids}, ATTR{{latency_timer}}="1"'
        return rule
    raise ConfigError(f"{port} is not a USB serial port this machine lists (python3 -m serial.tools.list_ports); "
                      "a Bluetooth port needs no rule: name it with --port")


def settings_from_args(args) -> config_mod.Config:
    cfg = config_mod.load(args.config)
    flags: dict[str, dict] = {}

    def put(section, key, value):
        if value is not None:
            flags.setdefault(section, {})[key] = value

    if args.replay:
        put("source", "kind", "replay")
        put("source.replay", "file", args.replay)
    elif args.simulate:
        put("source", "kind", "simulate")
    elif args.hid:
        put("source", "kind", "hid")
    elif args.port:
        put("source", "kind", "serial")
        put("source.serial", "port", args.port)
    put("source.replay", "speed", args.speed)
    put("source.simulate", "trace", args.trace)
    put("source.serial", "baud", args.baud)
    put("camera", "source", args.camera)
    put("output", "backend", args.backend)
    put("backend.x11", "display", args.display)
    put("mode", "start", args.mode)
    if args.sensitivity is not None:
        put("pointer", "slow_deg_per_width", args.sensitivity)
        put("pointer", "fast_deg_per_width", args.sensitivity)
    if args.no_stream:
        put("outputs.page", "enabled", False)
    put("outputs.page", "port", args.stream_port)
    if flags:
        cfg = cfg.with_overrides(flags, "command line")
    if args.set:
        cfg = cfg.with_overrides(config_mod.parse_set(args.set), "--set")
    config_mod.check_config(cfg, "settings")
    kind = sources.kind_of(cfg)  # a flag of another source than the one that runs would be dropped without a word
    if args.trace is not None and kind != "simulate":
        raise ConfigError(f"--trace {args.trace}: the motion the simulated sphere plays, but the source is {kind}: "
                          "use it with --simulate")
    if args.speed is not None and kind != "replay":
        raise ConfigError(f"--speed {args.speed:g}: the pace of a replay, but the source is {kind}: use it with --replay "
                          "FILE")
    return cfg


def open_source(cfg, log):
    """The source ``[source] kind`` names, from the registry (sphere.daemon.sources.REGISTRY)."""
    return sources.open_source(cfg, log)


class _JournalFormatter(logging.Formatter):
    """``sphere-mouse: message``; under systemd (stderr is the journal) prefixed with the syslog priority
    (``<4>`` warning, ``<6>`` info, sd-daemon(3)) so that `journalctl -p warning` finds the warnings."""

    PRIORITY = {logging.DEBUG: 7, logging.INFO: 6, logging.WARNING: 4, logging.ERROR: 3, logging.CRITICAL: 2}

    def __init__(self, journal: bool):
        super().__init__("sphere-mouse: %(message)s")
        self.journal = journal

    def format(self, record):
        text = super().format(record)
        return f"<{self.PRIORITY.get(record.levelno, 6)}>{text}" if self.journal else text


def _stderr_is_journal() -> bool:
    want = os.environ.get("JOURNAL_STREAM", "")
    try:
        st = os.fstat(sys.stderr.fileno())
        return want == f"{st.st_dev}:{st.st_ino}"
    except (OSError, ValueError, AttributeError):
        return False


def setup_logging(verbose: bool = False) -> logging.Logger:
    """The daemon's messages (logger "sphere.daemon" and its children) on stderr, one line each."""
    logger = logging.getLogger("sphere.daemon")
    for h in list(logger.handlers):
        if getattr(h, "_sphere_mouse", False):
            logger.removeHandler(h)
    handler = logging.StreamHandler(sys.stderr)
    handler._sphere_mouse = True
    handler.setFormatter(_JournalFormatter(_stderr_is_journal()))
    logger.addHandler(handler)
    logger.setLevel(logging.DEBUG if verbose else logging.INFO)
    logger.propagate = False
    return logger


def main(argv=None) -> int:
    try:
        return _main(argv)
    except KeyboardInterrupt:  # Ctrl-C before the signal handlers are in place (while starting)
        print("sphere-mouse: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `sphere-mouse --print-stats ... | head`: the reader has what it wanted
        try:  # and Python's last flush of stdout must not fail again
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError, AttributeError):
            pass
        return 0
    except OSError as e:  # --print-config or --udev-rule into a full disk
        code = output_failed("sphere-mouse", e)
        if code is None:
            raise
        return code


def _main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.print_config:
        sys.stdout.write(defaults_toml())
        return 0
    logger = setup_logging(args.verbose)

    def log(msg: str) -> None:
        logger.info(msg)

    try:
        cfg = settings_from_args(args)
    except ConfigError as e:
        logger.error(f"config error: {e}")
        return 2
    for note in cfg.notes:
        logger.warning(note)
    if args.udev_rule:
        try:
            print(udev_rule(args.udev_rule))
        except ConfigError as e:
            logger.error(str(e))
            return 2
        return 0
    if args.check_config:
        print(f"sphere-mouse: config OK ({cfg.origin})")
        return 0
    move_log = None
    if args.move_log:
        try:
            move_log = MoveLog(args.move_log)
        except MoveLogError as e:
            logger.error(str(e))
            return 2

    try:
        source = open_source(cfg, log)
    except (SourceError, ConfigError) as e:
        logger.error(str(e))
        return 2
    try:
        camera = CameraPosition.from_settings(cfg["camera"], log, source)  # None without [camera] source or a session
    except CameraUnavailable as e:
        logger.error(str(e))
        source.close()
        return 2
    try:
        backend = open_backend(cfg.output.backend, cfg.get, warn=logger.warning)
    except BackendUnavailable as e:
        logger.error(f"backend {cfg.output.backend} cannot start: {e}")
        source.close()
        if camera is not None:
            camera.close()
        return 2
    stream = attach(cfg, log)  # the 3-D page, OpenTrack, OSC, gamepad: each enabled one gets the pose
    status = None
    if not args.quiet and (args.status or sys.stderr.isatty()):
        status = StatusLine(sys.stderr, cfg.status.interval_s)
    daemon = SphereMouse(cfg, source, backend, stream=stream, status=status, camera=camera)
    daemon.move_log = move_log
    log(f"source {source.state}, backend {backend.NAME}, mode {daemon.mode}, "
        f"{cfg.pointer.slow_deg_per_width:g}° per screen width ({daemon.screen_width_px} px)")

    # the handlers only set flags; the loop acts on them between batches (no X, serial or log call in a handler)
    stops = [signal.SIGTERM, signal.SIGINT]
    if hasattr(signal, "SIGHUP") and signal.getsignal(signal.SIGHUP) is not signal.SIG_IGN:  # (nohup: left ignored)
        stops.append(signal.SIGHUP)  # its terminal closed: a stop as any other, the port and outputs closed
    for sig in stops:
        signal.signal(sig, lambda s, f: daemon.request("stop"))
    if hasattr(signal, "SIGUSR1"):
        signal.signal(signal.SIGUSR1, lambda s, f: daemon.request("recentre"))
        signal.signal(signal.SIGUSR2, lambda s, f: daemon.request("pause"))
    code = 0
    started = time.monotonic()
    try:
        daemon.run()
    except SourceFailed as e:  # a device that failed during the run
        logger.error(str(e))
        code = 1
    except BackendLost as e:  # the display the pointer moved on went away
        logger.error(f"backend {backend.NAME}: {e}")
        code = 1
    except SourceError as e:  # what the user named turned out unusable (a capture, a port, a protocol version)
        logger.error(str(e))
        code = 2
    finally:
        for sig in stops:
            signal.signal(sig, signal.SIG_DFL)
        source.close()
        backend.close()
        if camera is not None:
            camera.close()
        if stream is not None:
            stream.stop()
    if argv is None:  # the program itself (not a caller in-process): stopped and closed, only its last lines and
        # the interpreter's teardown (~0.2 s) are left; a double Ctrl-C's second press lands there and must not make
        # a finished run a death by SIGINT (exit status 130). During the closing above it still ends it at once.
        for sig in stops:
            signal.signal(sig, signal.SIG_IGN)
    log(f"stopped: {daemon.moves} pointer moves, {daemon.clicks} clicks, modes {daemon.mode_changes or [daemon.mode]}")
    if args.print_stats:
        print(run_stats(daemon, time.monotonic() - started), flush=True)
    if argv is None:  # the last lines are out: a further stop ends the teardown at once with this run's status (a
        # teardown that hangs, say on a thread that does not end, still ends on Ctrl-C or a plain kill). Python puts
        # its own handlers back to the default late in the interpreter's exit, after the threads are joined and the
        # atexit calls: from the first atexit call on the stops are ignored instead (this one, registered last,
        # runs first)
        for sig in stops:
            signal.signal(sig, lambda s, f: os._exit(code))
        atexit.register(lambda: [signal.signal(sig, signal.SIG_IGN) for sig in stops])
    return code
