"""sphere-mouse settings: each section a typed dataclass, declared once with its defaults, units and checks.

The same declarations validate ``~/.config/sphere-mouse/config.toml``, the ``--set SECTION.KEY=VALUE``
overrides and the command-line flags, and write the key reference in host/docs/sphere-mouse.md
(``python -m sphere.daemon.config --markdown``). A bad key or value stops the daemon at start with a
message that names the file, the key, what was given and what is allowed.

A module that needs settings of its own declares its section where it is used, and is listed once in
:data:`CONTRIBUTORS`::

    from sphere.daemon.config import option, section

    @section("pointer.smoothing")                # TOML [pointer.smoothing] (dotted = nested table)
    class PointerSmoothing:
        filter: str = option("none", "smoothing filter", choices=lambda: ("none", *REGISTRY))
        min_cutoff_hz: float = option(1.0, "…", check=positive)

        def check(self):                         # optional: keys that must agree; an error text or None
            return None

Types come from the annotations: ``float`` (a finite number; integers accepted), ``int``, ``bool``,
``str``, ``list`` (of strings unless a check says otherwise). ``choices`` is a tuple or a callable
returning one (a registry's names). ``register_section(name, cls)`` does the same without the decorator.
Values: ``cfg.pointer.slow_deg_per_width`` for undotted sections, ``cfg["pointer.smoothing"]`` for any.
"""

from __future__ import annotations

import dataclasses
import difflib
import importlib
import math
import os
import sys
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from sphere.smoothing.position import DEFAULT as _POSITION_SMOOTHING
from sphere.smoothing.registry import DEFAULT as _SMOOTHING  # the registry imports nothing of the daemon

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.9/3.10
    import tomli as tomllib

ACTIONS = (
    "none",
    "left_click",
    "right_click",
    "middle_click",
    "double_click",
    "next_mode",
    "recentre",
    "pause",
)
MODES = ("pointer", "tilt", "3d")

#: Modules that declare config sections of their own (imported before the settings are read). One line
#: per contributing module; a module that is not installed is skipped.
CONTRIBUTORS: tuple[str, ...] = (
    "sphere.daemon.outputs",
    "sphere.daemon.paths_config",  # [paths] (read by sphere.paths)  # [outputs.opentrack], [outputs.osc], [outputs.gamepad]
    "sphere.smoothing.config",  # [smoothing.NAME] for every filter of the smoothing registry
    "sphere.camera.daemon_source",  # [camera]: a webcam or video file giving the ball's position
)

#: The daemon's own sections, in the order the reference lists them (contributed ones follow).
CORE_ORDER = ("source", "output", "mode", "pointer", "tilt", "events", "freeze", "gyro", "orientation", "stream",
              "device", "status")

#: Keys of earlier releases that live elsewhere now: (section, key) -> what to write instead.
MOVED_KEYS = {
    ("pointer", "smoothing_dps"): "moved to [smoothing.tiered] smoothing_dps (the old smoothing is the filter "
                                  "`tiered`: [pointer] smoothing = \"tiered\"; the default is now `tremor`)",
    ("pointer", "smoothing_time_s"): "moved to [smoothing.tiered] smoothing_time_s (the old smoothing is the "
                                     "filter `tiered`: [pointer] smoothing = \"tiered\"; the default is now `tremor`)",
}

#: Largest integer a setting may hold (screen sizes, ports, IDs are far below; 2**70 is a typo).
MAX_INT = 1 << 31


class ConfigError(Exception):
    """A config file, override or flag that cannot be used; the message says which and why."""


# ---- declaring sections ----------------------------------------------------------------------------


def option(default, doc: str, check: Callable[[Any], str | None] | None = None, choices=None):
    """A key of a section: its default, what it means (for the reference), a check returning the reason a
    value is bad (or None), and the allowed values (a tuple, or a callable returning one)."""
    meta = {"doc": doc, "check": check, "choices": choices}
    if isinstance(default, list):
        frozen = list(default)
        return field(default_factory=lambda: list(frozen), metadata=meta)
    return field(default=default, metadata=meta)


SECTIONS: dict[str, type] = {}


def _as_dict(self) -> dict:
    return {f.name: _copy(getattr(self, f.name)) for f in dataclasses.fields(self)}


def register_section(name: str, cls: type) -> type:
    """Make ``cls`` (a class with :func:`option` fields) the section ``[name]``; returns the dataclass."""
    if not dataclasses.is_dataclass(cls):
        cls = dataclass(frozen=True)(cls)
    if not hasattr(cls, "as_dict"):
        cls.as_dict = _as_dict
    cls.SECTION = name
    SECTIONS[name] = cls
    _KINDS.pop(name, None)
    return cls


def section(name: str):
    """Class decorator: ``@section("stream")``; see :func:`register_section`."""
    return lambda cls: register_section(name, cls)


_contributors_loaded = False


def load_contributors() -> None:
    """Import the modules of :data:`CONTRIBUTORS` once, so that their sections are declared."""
    global _contributors_loaded
    if _contributors_loaded:
        return
    _contributors_loaded = True
    for module in CONTRIBUTORS:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as e:
            if e.name is None or not module.startswith(e.name):
                raise


def sections() -> dict[str, type]:
    """Every declared section, core ones first in :data:`CORE_ORDER`, each followed by its dotted children."""
    load_contributors()

    def key(name):
        top = name.split(".", 1)[0]
        return (CORE_ORDER.index(top) if top in CORE_ORDER else len(CORE_ORDER), top, name)

    return {n: SECTIONS[n] for n in sorted(SECTIONS, key=key)}


_KINDS: dict[str, dict[str, type]] = {}


def _kinds(name: str) -> dict[str, type]:
    """key → the annotated type (float, int, bool, str, list) of section ``name``."""
    got = _KINDS.get(name)
    if got is None:
        cls = SECTIONS[name]
        hints = typing.get_type_hints(cls)
        got = {}
        for f in dataclasses.fields(cls):
            t = hints[f.name]
            got[f.name] = typing.get_origin(t) or t
        _KINDS[name] = got
    return got


def _choices(f) -> tuple | None:
    c = f.metadata.get("choices")
    return tuple(c()) if callable(c) else c


# ---- checks -------------------------------------------------------------------------------------


def _positive(v):
    return None if v > 0 else "must be greater than 0"


def _non_negative(v):
    return None if v >= 0 else "must be 0 or more"


def _range(lo, hi):
    def check(v):
        return None if lo <= v <= hi else f"must be between {lo} and {hi}"

    return check


positive, non_negative, in_range = _positive, _non_negative, _range


def _port(v):
    return None if 0 <= v <= 65535 else "must be a TCP port number, 0 … 65535 (0 picks a free one)"


def _modes_list(v):
    if not v:
        return "must name at least one mode"
    bad = [m for m in v if m not in MODES]
    if bad:
        return f"has unknown mode(s) {bad}; modes are {list(MODES)}"
    return None


def _str_list(v):
    return None if all(isinstance(s, str) for s in v) else "must be a list of strings"


def _usb_ids(v):
    import re

    bad = [s for s in v if not isinstance(s, str) or not re.fullmatch(r"[0-9a-fA-F]{4}:[0-9a-fA-F]{4}", s)]
    return f"has {bad!r}: each entry is a USB VID:PID in hex, e.g. \"1a86:7523\"" if bad else None


def _baud(v):
    from sphere.link.port import check_baud

    return check_baud(v)


def _position_smoothing_names():
    from sphere.smoothing.position import FILTERS

    return tuple(FILTERS)


def _smoothing_names():
    from sphere.smoothing.registry import FILTERS

    return tuple(FILTERS)


def _source_kinds():
    from sphere.daemon.sources import REGISTRY

    return ("auto", *REGISTRY)


def _host_filters():
    """``auto`` and the filters the fusion registry marks live (only ``auto`` without sphere.fusion)."""
    try:
        from sphere.fusion.registry import LIVE
    except ImportError:
        return ("auto",)
    return ("auto", *LIVE)


# ---- the daemon's sections -----------------------------------------------------------------------


@section("source")
class SourceSettings:
    kind: str = option("auto", "where frames come from: `serial`, `hid`, `replay`, `simulate`, `scripted`; `auto` = "
                       "serial (with discovery), or `replay`/`simulate` when those flags are given",
                       choices=_source_kinds)
    port: str = option("auto", "serial port (`/dev/ttyUSB0`, `/dev/rfcomm0`, `/dev/sphere`); `auto` = discovery: the "
                       "ports in `candidates` and those whose USB IDs are in `usb_ids`, not held by another program, "
                       "listened to until one identifies itself as a sphere")
    candidates: list = option(["/dev/sphere"], "ports `port = \"auto\"` tries first: a literal path (the udev symlink) is "
                              "asked with GET_HELLO, a glob match is only listened to", _str_list)
    usb_ids: list = option(["1a86:7523", "0403:6001", "10c4:ea60"], "USB VID:PID of the sphere's USB-serial chip "
                           "(the Nano's CH340, FT232R, CP2102): such ports are listened to (never written to) until "
                           "they identify themselves; [] = only `candidates`", _usb_ids)
    baud: int = option(115200, "baud rate (the Nano's default; an HC-05/HC-06 must be set to the same)", _baud)
    reset_on_open: bool = option(False, "let opening the port reset a USB Nano through DTR; false holds DTR low "
                                 "(Linux still raises it for a moment on open, so a Nano with its auto-reset "
                                 "capacitor may reset anyway)")
    low_latency: bool = option(True, "ask the serial driver to pass bytes on at once (ASYNC_LOW_LATENCY: an FTDI "
                               "adapter's latency timer goes from 16 ms to 1 ms); false leaves the driver's default")
    hello_timeout_s: float = option(0.5, "send GET_HELLO to a named port if no HELLO came within this time (Bluetooth "
                                    "links do not reset the board)", _range(0.01, 60.0))
    discovery_timeout_s: float = option(3.0, "give up on a candidate port that did not identify itself within this "
                                        "time", _range(0.05, 600.0))
    link_timeout_s: float = option(2.0, "a connected port that delivers no byte for this long is taken as lost (a "
                                   "Bluetooth link that dropped) and reopened", _range(0.05, 3600.0))
    reconnect_interval_s: float = option(1.0, "pause between attempts to find the sphere again", _range(0.01, 3600.0))
    replay: str = option("", "capture file to replay (same as `--replay`)")
    speed: float = option(1.0, "replay speed: 1 = as recorded, 4 = four times faster, 0 = as fast as possible",
                          _range(0.0, 1e6))
    hid_vendor_id: int = option(0, "USB vendor ID of a HID receiver (0 = any device whose product string contains "
                                "`hid_product`)", _range(0, 0xFFFF))
    hid_product_id: int = option(0, "USB product ID of a HID receiver (0 = any)", _range(0, 0xFFFF))
    hid_product: str = option("sphere", "substring of the HID product string looked for when no IDs are set")
    sim_seconds: float = option(600.0, "how long the virtual board runs with `--simulate` (the daemon ends with it)",
                                _range(1.0, 86400.0))
    sim_trace: str = option("", "motion the virtual board plays with `--simulate`: a BROAD trial (.mat, name or "
                            "number) or `synthetic:NAME` (see `sphere sim --help`); empty = the tour, `synthetic:tour`")

    def check(self):
        if self.kind == "replay" and not self.replay:
            return 'kind = "replay" needs a capture file: --replay FILE or [source] replay = "FILE"'
        return None


@section("output")
class OutputSettings:
    backend: str = option("auto", "`uinput` (Linux, X11 and Wayland), `x11` (XTest), `pynput` (macOS, Windows), "
                          "`log` (print only); `auto` tries uinput, x11, pynput, then falls back to log and says why",
                          choices=("auto", "uinput", "x11", "pynput", "log"))
    display: str = option("", "X display for the x11 backend (empty = `$DISPLAY`)")
    screen_width_px: int = option(0, "screen width used to turn degrees into pixels; 0 = ask the backend (x11, "
                                  "pynput; uinput asks the X display if there is one), else 1920", _range(0, 100000))


@section("mode")
class ModeSettings:
    start: str = option("pointer", "mode at start", choices=MODES)
    cycle: list = option(["pointer", "tilt", "3d"], "modes that `next_mode` steps through, in order", _modes_list)


@section("pointer")
class PointerConfig:
    slow_deg_per_width: float = option(40.0, "degrees of wrist rotation that move the pointer one screen width when "
                                       "turning slowly (below `accel_low_dps`)", _range(0.5, 3600.0))
    fast_deg_per_width: float = option(40.0, "the same when turning fast (above `accel_high_dps`); smaller than "
                                       "`slow_deg_per_width` = acceleration; equal = none", _range(0.5, 3600.0))
    accel_low_dps: float = option(20.0, "rotation speed (°/s) up to which the slow sensitivity applies",
                                  _range(0.0, 2000.0))
    accel_high_dps: float = option(120.0, "rotation speed (°/s) from which the fast sensitivity applies; between the "
                                   "two it is blended linearly", _range(0.001, 5000.0))
    tightening_dps: float = option(1.0, "rotations slower than this are scaled down in proportion to their speed "
                                   "(soft, instead of a dead zone that swallows them); 0 = off", _range(0.0, 100.0))
    smoothing: str = option(_SMOOTHING, "smoothing filter of the pointer, from the smoothing registry (its parameters "
                            "in [smoothing.NAME]); `tremor` takes out the hand's 8–12 Hz tremor, `none` = off",
                            choices=_smoothing_names)
    axes: str = option("world", "`world`: turning about the vertical moves the pointer sideways however the sphere is "
                       "rolled (uses gravity); `local`: the sensor's own z (yaw) and y (pitch) axes",
                       choices=("world", "local"))
    invert_x: bool = option(False, "swap left and right")
    invert_y: bool = option(False, "swap up and down")

    def check(self):
        if self.accel_high_dps <= self.accel_low_dps:
            return (f"accel_high_dps = {self.accel_high_dps} must be greater than accel_low_dps = "
                    f"{self.accel_low_dps}")
        return None


@section("tilt")
class TiltConfig:
    dead_zone_deg: float = option(3.0, "tilt from the recentred pose that does not move the pointer", _range(0.0, 45.0))
    full_speed_deg: float = option(25.0, "tilt at which the pointer reaches `max_speed_px_s`", _range(1.0, 90.0))
    max_speed_px_s: float = option(1200.0, "pointer speed at full tilt", _range(1.0, 100000.0))
    exponent: float = option(1.5, "response curve between dead zone and full tilt (1 = linear)", _range(0.5, 4.0))

    def check(self):
        if self.full_speed_deg <= self.dead_zone_deg:
            return f"full_speed_deg = {self.full_speed_deg} must be greater than dead_zone_deg = {self.dead_zone_deg}"
        return None


@section("events")
class EventsConfig:
    single_tap: str = option("left_click", "action of a single tap", choices=ACTIONS)
    double_tap: str = option("double_click", "action of a double tap (`double_click` counts the single tap's click as "
                             "the first one)", choices=ACTIONS)
    free_fall: str = option("next_mode", "action of a free fall (toss and catch)", choices=ACTIONS)
    single_tap_wait_ms: int = option(0, "hold a single tap's action this long and drop it if a double tap follows (use "
                                     "with `double_tap = \"right_click\"`); 0 = act at once", _range(0, 1000))


@section("freeze")
class FreezeConfig:
    tap_before_ms: int = option(80, "pointer motion in this time before a tap is undone, so the click lands where the "
                                "pointer was aimed before the knock jolted it", _range(0, 1000))
    tap_after_ms: int = option(150, "the pointer stays still this long after a tap", _range(0, 2000))
    free_fall_before_ms: int = option(400, "motion undone before a free fall (the toss)", _range(0, 3000))
    free_fall_after_ms: int = option(700, "the pointer stays still this long after a free fall (the catch)",
                                     _range(0, 5000))


@section("gyro")
class GyroConfig:
    auto_bias: bool = option(True, "re-estimate the gyroscope bias on the host whenever the sphere lies still")
    still_dps: float = option(3.0, "the sphere counts as still while every gyro axis stays within this of its mean",
                              _range(0.01, 100.0))
    still_time_s: float = option(1.0, "how long it must be still for a bias update", _range(0.1, 30.0))


@section("orientation")
class OrientationConfig:
    source: str = option("auto", "`host`: the host's fusion filter on RAW_SAMPLE; `device`: the firmware's ORIENTATION "
                         "packets; `auto` = host when raw samples arrive and sphere.fusion is installed",
                         choices=("auto", "host", "device"))
    use_mag: bool = option(False, "let the host filter use the magnetometer (needs a calibrated one; without it yaw "
                           "drifts slowly, which pointing does not mind)")
    filter: str = option("auto", "host filter: `sphere` (sphere.fusion's SphereFilter: rejects taps, vibration and hand "
                         "acceleration, learns the gyro bias at rest), `madgwick`; `auto` = the best installed",
                         choices=_host_filters)
    beta: float = option(0.1, "gain β (rad/s) of the host Madgwick filter", _range(0.0, 2.0))


@section("stream")
class StreamConfig:
    enabled: bool = option(True, "serve orientation on a WebSocket and the 3-D page over HTTP")
    host: str = option("127.0.0.1", "address to listen on (keep it local)")
    port: int = option(8765, "TCP port of the WebSocket and the page (http://127.0.0.1:PORT/)", _port)
    rate_hz: float = option(60.0, "orientation messages per second", _range(1.0, 200.0))
    smoothing: str = option(_SMOOTHING, "smoothing filter of the streamed orientation, from the smoothing registry "
                            "(its parameters in [smoothing.NAME], degrees); `none` = the orientation as measured",
                            choices=_smoothing_names)
    position_smoothing: str = option(_POSITION_SMOOTHING, "smoothing filter of the streamed position (with a camera), "
                                     "its parameters in metres in [position_smoothing.NAME]; `none` = the hybrid "
                                     "tracker's estimate as it is", choices=_position_smoothing_names)
    max_clients: int = option(16, "most WebSocket and page connections at once; more are refused (503)",
                              _range(1, 1000))


def _device_settings(items) -> str | None:
    from sphere.link.device_settings import SettingError, parse_assignment  # the settings' own checks

    seen = set()
    try:
        for item in items:
            key, _ = parse_assignment(item)
            if key in seen:
                return f"{key} given twice"
            seen.add(key)
    except SettingError as e:
        return str(e)
    return None


@section("device")
class DeviceConfig:
    settings: list = option([], "device settings sent to the sphere at every connect, as `sphere device set` takes "
                            "them (`sphere device keys` lists them), e.g. [\"tap.threshold_g=2.5\", \"tap.axes=z\"]; "
                            "they win over what the sphere saved (`sphere device save`), which it keeps for other "
                            "programs; empty = the sphere's own", _device_settings)


@section("status")
class StatusConfig:
    interval_s: float = option(1.0, "how often the status line is refreshed", _range(0.05, 3600.0))


# ---- values ---------------------------------------------------------------------------------------


class Config:
    """All settings; ``Config()`` is the defaults. ``values`` are already validated (``{section: {key: value}}``)."""

    def __init__(self, values: dict | None = None, origin: str = "defaults"):
        self.origin = origin
        self._sections = {}
        values = values or {}
        for name, cls in sections().items():
            obj = cls(**values.get(name, {}))
            self._sections[name] = obj
            if "." not in name:
                setattr(self, name, obj)

    def __getitem__(self, name: str):
        return self._sections[name]

    def as_dict(self) -> dict:
        return {name: obj.as_dict() for name, obj in self._sections.items()}

    def with_overrides(self, overrides: dict, origin: str) -> "Config":
        """A copy with ``{section: {key: value}}`` validated and applied."""
        checked = validate(overrides, origin, together=False)
        values = self.as_dict()
        for s, keys in checked.items():
            values[s].update(keys)
        return Config(values, origin=self.origin)


def _copy(v):
    return list(v) if isinstance(v, list) else v


def default_path() -> Path:
    base = os.environ.get("XDG_CONFIG_HOME") or os.path.join(os.path.expanduser("~"), ".config")
    return Path(base) / "sphere-mouse" / "config.toml"


def _suggest(word: str, options) -> str:
    close = difflib.get_close_matches(word, list(options), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _type_name(kind) -> str:
    return {float: "a number", bool: "true or false", int: "an integer", str: "a string", list: "a list"}.get(
        kind, str(kind))


def check_value(section_name: str, key: str, value, where: str):
    """The value converted to the key's type, or ConfigError saying what is wrong."""
    cls = SECTIONS[section_name]
    f = cls.__dataclass_fields__[key]
    kind = _kinds(section_name)[key]
    label = f"{where}: [{section_name}] {key} = {value!r}"
    doc = f.metadata.get("doc", "")
    if kind is float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        if ok:
            try:
                value = float(value)
            except OverflowError:
                raise ConfigError(f"{label}: is too large") from None
            if not math.isfinite(value):
                raise ConfigError(f"{label}: must be a finite number")
    elif kind is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
        if ok and abs(value) > MAX_INT:
            raise ConfigError(f"{label}: is too large")
    else:
        ok = isinstance(value, kind)
    if not ok:
        raise ConfigError(f"{label}: must be {_type_name(kind)}. {doc}")
    choices = _choices(f)
    if choices is not None and value not in choices:
        raise ConfigError(f"{label}: must be one of {', '.join(map(repr, choices))}{_suggest(str(value), choices)}")
    check = f.metadata.get("check")
    if check is not None:
        reason = check(value)
        if reason:
            raise ConfigError(f"{label}: {reason}")
    return value


def flatten(values: dict, where: str) -> dict:
    """``{"pointer": {"smoothing": {...}}}`` (nested TOML tables) → ``{"pointer.smoothing": {...}}``."""
    known = sections()
    prefixes = {n.rsplit(".", 1)[0] for n in known if "." in n}
    out: dict[str, dict] = {}

    def walk(name, table):
        if not isinstance(table, dict):
            raise ConfigError(f"{where}: {name} must be a [{name}] table, not a value")
        for key, value in table.items():
            sub = f"{name}.{key}"
            if isinstance(value, dict) and (sub in known or sub in prefixes):
                walk(sub, value)
            elif name in known:
                out.setdefault(name, {})[key] = value
            else:
                raise ConfigError(f"{where}: unknown section [{sub if isinstance(value, dict) else name}]"
                                  f"{_suggest(sub, known)}; sections are {', '.join(known)}")
        if name in known:
            out.setdefault(name, {})

    for name, table in values.items():
        if name not in known and name not in prefixes:
            raise ConfigError(f"{where}: unknown section [{name}]{_suggest(name, known)}; sections are "
                              f"{', '.join(known)}")
        walk(name, table)
    return out


def validate(values: dict, where: str, together: bool = True) -> dict:
    """Check a ``{section: {key: value}}`` mapping (nested or dotted section names); returns the converted
    values with dotted section names."""
    out: dict[str, dict] = {}
    for name, keys in flatten(values, where).items():
        fields = SECTIONS[name].__dataclass_fields__
        for key, value in keys.items():
            if key not in fields and (name, key) in MOVED_KEYS:
                raise ConfigError(f"{where}: [{name}] {key} {MOVED_KEYS[name, key]}")
            if key not in fields:
                raise ConfigError(f"{where}: unknown key [{name}] {key}{_suggest(key, fields)}; keys of [{name}] are "
                                  f"{', '.join(fields)}")
            out.setdefault(name, {})[key] = check_value(name, key, value, where)
    if together:
        _check_together(out, where)
    return out


def _check_together(values: dict, where: str) -> None:
    """Keys that must agree, for the sections present in ``values`` (a dict, or a Config's as_dict())."""
    for name, keys in values.items():
        cls = SECTIONS.get(name)
        if cls is None or not hasattr(cls, "check") or not keys:
            continue
        try:
            obj = cls(**keys)
        except TypeError:
            continue
        reason = obj.check()
        if reason:
            raise ConfigError(f"{where}: [{name}] {reason}")


def check_config(cfg: Config, where: str) -> None:
    """The cross-key checks on a whole Config (a key from the file with another one's default)."""
    for name, obj in cfg._sections.items():
        check = getattr(obj, "check", None)
        reason = check() if check else None
        if reason:
            raise ConfigError(f"{where}: [{name}] {reason}")


def load(path: Path | str | None = None, required: bool = False) -> Config:
    """Read and validate a config file. A missing default file means defaults; a missing named one is an error."""
    explicit = path is not None
    path = Path(path) if explicit else default_path()
    try:
        exists = path.exists()
    except OSError as e:  # a folder on the way that cannot be searched
        raise ConfigError(f"{path}: cannot read: {e.strerror}") from None
    if not exists:
        if explicit or required:
            raise ConfigError(f"{path}: no such config file")
        return Config()
    if path.is_dir():
        raise ConfigError(f"{path} is a folder, not a config file")
    if not path.is_file() and str(path) != os.devnull:  # a device or a FIFO: reading it might never end
        raise ConfigError(f"{path} is not a regular file: give a TOML text file (sphere-mouse --print-config writes one)")
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML: {e}") from None
    except UnicodeDecodeError as e:
        raise ConfigError(f"{path}: not a UTF-8 text file (byte {e.start}): save it as UTF-8") from None
    except OSError as e:
        raise ConfigError(f"{path}: cannot read: {e.strerror}") from None
    checked = validate(data, str(path))
    cfg = Config(checked, origin=str(path))
    check_config(cfg, str(path))  # relations between keys: one key in the file, the other a default
    return cfg


def parse_set(items: list[str]) -> dict:
    """``["pointer.axes=local", "pointer.smoothing.filter=one_euro"]`` → ``{section: {key: value}}``, values
    parsed as TOML values (a bare word is taken as a string)."""
    out: dict[str, dict] = {}
    for item in items:
        if "=" not in item or "." not in item.split("=", 1)[0]:
            raise ConfigError(f"--set {item!r}: expected SECTION.KEY=VALUE, e.g. pointer.axes=local")
        name, text = item.split("=", 1)
        section_name, key = name.strip().rsplit(".", 1)
        try:
            value = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = text.strip()  # a bare word: take it as a string (pointer.axes=local)
        out.setdefault(section_name, {})[key] = value
    return out


def markdown() -> str:
    """The key reference, as a Markdown table per section."""
    lines = []
    for name, cls in sections().items():
        lines += [f"### [{name}]", "", "| key | default | meaning |", "|---|---|---|"]
        defaults = cls()
        for f in dataclasses.fields(cls):
            default = getattr(defaults, f.name)
            if isinstance(default, bool):
                shown = "true" if default else "false"
            elif isinstance(default, str):
                shown = f'"{default}"'
            elif isinstance(default, list):
                shown = "[" + ", ".join(f'"{v}"' for v in default) + "]"
            else:
                shown = repr(default)
            doc = f.metadata.get("doc", "").replace("|", "\\|")
            choices = _choices(f)
            if choices and "`" not in doc:
                doc += " (" + ", ".join(f"`{c}`" for c in choices) + ")"
            lines.append(f"| `{f.name}` | `{shown}` | {doc} |")
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover
    if "--markdown" in sys.argv:
        # run as __main__, this file is a second module: the contributed sections register with the real one
        from sphere.daemon import config as _config

        print(_config.markdown())
