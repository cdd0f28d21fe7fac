"""Command-line flags of sphere-mouse, and putting the daemon together from them and the config file."""

from __future__ import annotations

import argparse
import signal
import sys

from sphere.daemon import config as config_mod
from sphere.daemon.config import ConfigError

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
    src.add_argument("--trace", help="motion trace (.mat) for --simulate")
    src.add_argument("--baud", type=int, help="serial baud rate (default 115200)")
    out = p.add_argument_group("output")
    out.add_argument("--backend", choices=("auto", "uinput", "x11", "pynput", "log"),
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
    p.add_argument("--check-config", action="store_true", help="validate the config and exit")
    return p


def settings_from_args(args) -> config_mod.Config:
    cfg = config_mod.load(args.config)
    flags: dict[str, dict] = {}

    def put(section, key, value):
        if value is not None:
            flags.setdefault(section, {})[key] = value

    if args.replay:
        put("source", "kind", "replay")
        put("source", "replay", args.replay)
    elif args.simulate:
        put("source", "kind", "simulate")
    elif args.hid:
        put("source", "kind", "hid")
    elif args.port:
        put("source", "kind", "serial")
        put("source", "port", args.port)
    put("source", "speed", args.speed)
    put("source", "sim_trace", args.trace)
    put("source", "baud", args.baud)
    put("output", "backend", args.backend)
    put("output", "display", args.display)
    put("mode", "start", args.mode)
    if args.sensitivity is not None:
        put("pointer", "slow_deg_per_width", args.sensitivity)
        put("pointer", "fast_deg_per_width", args.sensitivity)
    if args.no_stream:
        put("stream", "enabled", False)
    put("stream", "port", args.stream_port)
    if flags:
        cfg = cfg.with_overrides(flags, "command line")
    if args.set:
        cfg = cfg.with_overrides(config_mod.parse_set(args.set), "--set")
    merged = cfg.as_dict()
    config_mod._check_together(merged, "settings")
    return cfg


def open_source(cfg, log):
    from sphere.daemon import sources

    s = cfg.source
    kind = s.kind
    if kind == "auto":
        kind = "replay" if s.replay else "serial"
    if kind == "replay":
        if not s.replay:
            raise ConfigError("[source] kind = \"replay\" needs a capture file: --replay FILE or [source] replay")
        return sources.ReplaySource(s.replay, s.speed)
    serial_kwargs = dict(baud=s.baud, hello_timeout_s=s.hello_timeout_s, discovery_timeout_s=s.discovery_timeout_s,
                         link_timeout_s=s.link_timeout_s, reconnect_interval_s=s.reconnect_interval_s)
    if kind == "simulate":
        if sources.simulator_available():
            try:
                return sources.SimulatorSource(s.sim_trace, log=log, seconds=s.sim_seconds, **serial_kwargs)
            except sources.SourceError as e:
                log(f"the virtual board cannot run here ({e}); using the built-in scripted sphere")
        else:
            log("the virtual board (sphere sim) is not installed here; using the built-in scripted sphere")
        return sources.ScriptedSource(speed=s.speed or 1.0)
    if kind == "hid":
        return sources.HidSource(s.hid_vendor_id, s.hid_product_id, s.hid_product,
                                 reconnect_interval_s=s.reconnect_interval_s, log=log)
    return sources.SerialSource(s.port, s.candidates, reset_on_open=s.reset_on_open, log=log, **serial_kwargs)


def main(argv=None) -> int:
    try:
        return _main(argv)
    except KeyboardInterrupt:  # Ctrl-C before the signal handlers are in place (while starting)
        print("sphere-mouse: interrupted", file=sys.stderr)
        return 130


def _main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)

    def log(msg: str) -> None:
        print(f"sphere-mouse: {msg}", file=sys.stderr, flush=True)

    try:
        cfg = settings_from_args(args)
    except ConfigError as e:
        print(f"sphere-mouse: config error: {e}", file=sys.stderr)
        return 2
    if args.check_config:
        print(f"sphere-mouse: config OK ({cfg.origin})")
        return 0

    from sphere.daemon.app import SphereMouse
    from sphere.daemon.backends import BackendUnavailable, open_backend
    from sphere.daemon.sources import SourceError
    from sphere.daemon.status import StatusLine

    try:
        source = open_source(cfg, log)
    except (SourceError, ConfigError) as e:
        log(str(e))
        return 2
    try:
        backend = open_backend(cfg.output.backend, cfg.output.display, warn=log)
    except BackendUnavailable as e:
        log(f"backend {cfg.output.backend} cannot start: {e}")
        return 2
    stream = None
    if cfg.stream.enabled:
        try:
            from sphere.daemon.stream3d import OrientationStream

            stream = OrientationStream(cfg.stream.host, cfg.stream.port, cfg.stream.rate_hz, log=log)
            stream.start()
            log(f"3-D view on http://{cfg.stream.host}:{stream.port}/ (WebSocket ws://{cfg.stream.host}:{stream.port}/ws)")
        except Exception as e:  # a taken port must not stop the pointer
            log(f"no 3-D stream: {e}")
            stream = None
    status = None
    if not args.quiet and (args.status or sys.stderr.isatty()):
        status = StatusLine(sys.stderr, cfg.status.interval_s)
    daemon = SphereMouse(cfg, source, backend, stream=stream, status=status, log=log)
    log(f"source {source.state}, backend {backend.name}, mode {daemon.mode}, "
        f"{cfg.pointer.slow_deg_per_width:g}° per screen width ({daemon.screen_width_px} px)")

    def on_stop(signum, frame):
        daemon.stop()

    signal.signal(signal.SIGTERM, on_stop)
    signal.signal(signal.SIGINT, on_stop)
    if hasattr(signal, "SIGUSR1"):
        signal.signal(signal.SIGUSR1, lambda s, f: daemon.recentre())
        signal.signal(signal.SIGUSR2, lambda s, f: daemon.toggle_pause())
    code = 0
    try:
        daemon.run()
    except SourceError as e:
        log(str(e))
        code = 2
    finally:
        source.close()
        backend.close()
        if stream is not None:
            stream.stop()
    log(f"stopped: {daemon.moves} pointer moves, {daemon.clicks} clicks, modes {daemon.mode_changes or [daemon.mode]}")
    return code
