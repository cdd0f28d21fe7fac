"""sphere-mouse settings: the sections of ``~/.config/sphere-mouse/config.toml``, composed from the parameters
(:class:`sphere.settings.Param`) the parts of the daemon declare.

Each section is a dict of ``Param`` (default, unit, range or choices, meaning), written once where it is
used: the daemon's own sections in :data:`CORE` here, and one section per registered component, composed
from the registries in :data:`REGISTRIES` (``[smoothing.tremor]`` from the smoothing filter ``tremor``'s
``PARAMS``, ``[outputs.osc]`` from the OSC output's, ``[camera]`` from the camera's ...). The same
declarations validate the file, the ``--set SECTION.KEY=VALUE`` overrides and the command-line flags, and
write ``--print-config`` and the key reference in host/docs/sphere-mouse.md (``python -m
sphere.daemon.config --markdown``). A bad key or value stops the daemon at start with a message that names
the file, the key, what was given and what is allowed.

Values: ``cfg.pointer.slow_deg_per_width`` for undotted sections, ``cfg["smoothing.tremor"]`` for any (a
:class:`sphere.settings.Settings`). Importing this module imports no component: the registries are read
when a :class:`Config` is first made.
"""

from __future__ import annotations

import difflib
import sys
from pathlib import Path

from sphere import paths
from sphere.errors import SphereError
from sphere.settings import Param, ParamError, Registry, Settings, load as load_object
from sphere.smoothing.registry import DEFAULT as _SMOOTHING
from sphere.smoothing.registry import POSITION as _POSITION_FILTERS
from sphere.smoothing.registry import POSITION_DEFAULT as _POSITION_SMOOTHING
from sphere.smoothing.registry import REGISTRY as _SMOOTHING_FILTERS

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

#: Parts configured by one section each, ``[NAME]``: NAME → "module:Class" (a class with ``PARAMS``).
PARTS = Registry("part", {
    "camera": "sphere.camera.daemon_source:CameraPosition",  # a webcam or video file giving the ball's position
    "paths": "sphere.daemon.paths_config:PathsSettings",  # [paths] (read by sphere.paths)
    "gyro_bias": "sphere.daemon.gyro_bias:GyroBias",  # the host's one gyro-bias estimate (its [gyro] keys stay there)
    "rest_hold": "sphere.daemon.gyro_bias:RestHold",  # the pointer held while the sphere lies still
}, section="{name}")

#: Every registry whose components have a section of their own: "module:attribute" of a
#: :class:`sphere.settings.Registry`, imported when the sections are first composed.
REGISTRIES: tuple[str, ...] = (
    "sphere.daemon.outputs:REGISTRY",  # [outputs.NAME]
    "sphere.smoothing.registry:REGISTRY",  # [smoothing.NAME]
    "sphere.smoothing.registry:POSITION",  # [position_smoothing.NAME]
    "sphere.daemon.config:PARTS",  # [camera], [paths]
)

#: The sections in the order the reference lists them (by their first part; others follow).
ORDER = ("source", "output", "mode", "pointer", "tilt", "events", "freeze", "gyro", "gyro_bias", "rest_hold",
         "orientation", "stream",
         "device", "status", "outputs", "smoothing", "position_smoothing", "paths", "camera")

#: Keys of earlier releases that live elsewhere now: (section, key) -> what to write instead.
MOVED_KEYS = {
    ("pointer", "smoothing_dps"): "moved to [smoothing.tiered] smoothing_dps (the old smoothing is the filter "
                                  "`tiered`: [pointer] smoothing = \"tiered\"; the default is now `tremor`)",
    ("pointer", "smoothing_time_s"): "moved to [smoothing.tiered] smoothing_time_s (the old smoothing is the "
                                     "filter `tiered`: [pointer] smoothing = \"tiered\"; the default is now `tremor`)",
}


class ConfigError(SphereError):
    """A config file, override or flag that cannot be used; the message says which and why."""


# ---- checks a range cannot say -------------------------------------------------------------------


def positive(v):
    return None if v > 0 else "must be greater than 0"


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


_HEX = frozenset("0123456789abcdefABCDEF")


def _usb_id(s) -> bool:
    return isinstance(s, str) and len(s) == 9 and s[4] == ":" and _HEX.issuperset(s[:4] + s[5:])


def _usb_ids(v):
    bad = [s for s in v if not _usb_id(s)]
    return f"has {bad!r}: each entry is a USB VID:PID in hex, e.g. \"1a86:7523\"" if bad else None


def _baud(v):
    from sphere.link.port import check_baud  # TODO(step 2): the serial source's own PARAMS

    return check_baud(v)


def _smoothing_names():
    return tuple(_SMOOTHING_FILTERS)


def _source_kinds():
    from sphere.daemon.sources import REGISTRY

    return ("auto", *REGISTRY)


def _host_filters():
    """``auto`` and the filters the fusion registry marks live (only ``auto`` without sphere.fusion)."""
    try:
        from sphere.fusion.registry import live_available
    except ImportError:
        return ("auto",)
    return ("auto", *live_available())


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


def _check_source(s):
    if s.kind == "replay" and not s.replay:
        return 'kind = "replay" needs a capture file: --replay FILE or [source] replay = "FILE"'
    return None


def _check_pointer(s):
    if s.accel_high_dps <= s.accel_low_dps:
        return f"accel_high_dps = {s.accel_high_dps} must be greater than accel_low_dps = {s.accel_low_dps}"
    return None


def _check_tilt(s):
    if s.full_speed_deg <= s.dead_zone_deg:
        return f"full_speed_deg = {s.full_speed_deg} must be greater than dead_zone_deg = {s.dead_zone_deg}"
    return None


# ---- the daemon's own sections ---------------------------------------------------------------------

#: section → its parameters
CORE: dict[str, dict[str, Param]] = {
    "source": {
        "kind": Param("auto", doc="where frames come from: `serial`, `hid`, `replay`, `simulate`, `scripted`; `auto` = "
                           "serial (with discovery), or `replay`/`simulate` when those flags are given", choices=_source_kinds),
        "port": Param("auto", doc="serial port (`/dev/ttyUSB0`, `/dev/rfcomm0`, `/dev/sphere`); `auto` = discovery: the "
                           "ports in `candidates` and those whose USB IDs are in `usb_ids`, not held by another program, "
                           "listened to until one identifies itself as a sphere"),
        "candidates": Param(["/dev/sphere"], doc="ports `port = \"auto\"` tries first: a literal path (the udev symlink) is "
                                  "asked with GET_HELLO, a glob match is only listened to", check=_str_list),
        "usb_ids": Param(["1a86:7523", "0403:6001", "10c4:ea60"], doc="USB VID:PID of the sphere's USB-serial chip "
                               "(the Nano's CH340, FT232R, CP2102): such ports are listened to (never written to) until "
                               "they identify themselves; [] = only `candidates`", check=_usb_ids),
        "baud": Param(115200, doc="baud rate (the Nano's default; an HC-05/HC-06 must be set to the same)", check=_baud),
        "reset_on_open": Param(False, doc="let opening the port reset a USB Nano through DTR; false holds DTR low "
                                     "(Linux still raises it for a moment on open, so a Nano with its auto-reset "
                                     "capacitor may reset anyway)"),
        "low_latency": Param(True, doc="ask the serial driver to pass bytes on at once (ASYNC_LOW_LATENCY: an FTDI "
                             "adapter's latency timer goes from 16 ms to 1 ms); false leaves the driver's default"),
        "baud_switch": Param(1000000, doc="on a USB link, move a version-3 sphere to this exact rate after it connects "
                             "(SET_BAUD, confirmed, back to 115200 when either side stops hearing the other; a 29-byte "
                             "sample takes 0.29 ms at 1,000,000 instead of 2.5 ms); 0 = stay at `baud`. Never on "
                             "Bluetooth", choices=(0, 250000, 500000, 1000000)),
        "hello_timeout_s": Param(0.5, doc="send GET_HELLO to a named port if no HELLO came within this time (Bluetooth "
                                        "links do not reset the board)", lo=0.01, hi=60.0),
        "discovery_timeout_s": Param(3.0, doc="give up on a candidate port that did not identify itself within this "
                                            "time", lo=0.05, hi=600.0),
        "link_timeout_s": Param(2.0, doc="a connected port that delivers no byte for this long is taken as lost (a "
                                       "Bluetooth link that dropped) and reopened", lo=0.05, hi=3600.0),
        "reconnect_interval_s": Param(1.0, doc="pause between attempts to find the sphere again", lo=0.01, hi=3600.0),
        "replay": Param("", doc="capture file to replay (same as `--replay`)"),
        "speed": Param(1.0, doc="replay speed: 1 = as recorded, 4 = four times faster, 0 = as fast as possible", lo=0.0, hi=1e6),
        "hid_vendor_id": Param(0, doc="USB vendor ID of a HID receiver (0 = any device whose product string contains "
                                    "`hid_product`)", lo=0, hi=0xFFFF),
        "hid_product_id": Param(0, doc="USB product ID of a HID receiver (0 = any)", lo=0, hi=0xFFFF),
        "hid_product": Param("sphere", doc="substring of the HID product string looked for when no IDs are set"),
        "sim_seconds": Param(600.0, doc="how long the virtual board runs with `--simulate` (the daemon ends with it)", lo=1.0, hi=86400.0),
        "sim_trace": Param("", doc="motion the virtual board plays with `--simulate`: a BROAD trial (.mat, name or "
                                "number) or `synthetic:NAME` (see `sphere sim --help`); empty = the tour, `synthetic:tour`"),
    },
    "output": {
        "backend": Param("auto", doc="`uinput` (Linux, X11 and Wayland), `x11` (XTest), `pynput` (macOS, Windows), "
                              "`log` (print only); `auto` tries uinput, x11, pynput, then falls back to log and says why", choices=("auto", "uinput", "x11", "pynput", "log")),
        "display": Param("", doc="X display for the x11 backend (empty = `$DISPLAY`)"),
        "screen_width_px": Param(0, doc="screen width used to turn degrees into pixels; 0 = ask the backend (x11, "
                                      "pynput; uinput asks the X display if there is one), else 1920", lo=0, hi=100000),
    },
    "mode": {
        "start": Param("pointer", doc="mode at start", choices=MODES),
        "cycle": Param(["pointer", "tilt", "3d"], doc="modes that `next_mode` steps through, in order", check=_modes_list),
    },
    "pointer": {
        "slow_deg_per_width": Param(40.0, doc="degrees of wrist rotation that move the pointer one screen width when "
                                           "turning slowly (below `accel_low_dps`)", lo=0.5, hi=3600.0),
        "fast_deg_per_width": Param(40.0, doc="the same when turning fast (above `accel_high_dps`); smaller than "
                                           "`slow_deg_per_width` = acceleration; equal = none", lo=0.5, hi=3600.0),
        "accel_low_dps": Param(20.0, doc="rotation speed (°/s) up to which the slow sensitivity applies", lo=0.0, hi=2000.0),
        "accel_high_dps": Param(120.0, doc="rotation speed (°/s) from which the fast sensitivity applies; between the "
                                       "two it is blended linearly", lo=0.001, hi=5000.0),
        "tightening_dps": Param(1.0, doc="rotations slower than this are scaled down in proportion to their speed "
                                       "(soft, instead of a dead zone that swallows them); 0 = off", lo=0.0, hi=100.0),
        "smoothing": Param(_SMOOTHING, doc="smoothing filter of the pointer, from the smoothing registry (its parameters "
                                "in [smoothing.NAME]); `tremor` takes out the hand's 8–12 Hz tremor, `none` = off", choices=_smoothing_names),
        "axes": Param("world", doc="`world`: turning about the vertical moves the pointer sideways however the sphere is "
                           "rolled (uses gravity); `local`: the sensor's own z (yaw) and y (pitch) axes", choices=("world", "local")),
        "invert_x": Param(False, doc="swap left and right"),
        "invert_y": Param(False, doc="swap up and down"),
    },
    "tilt": {
        "dead_zone_deg": Param(3.0, doc="tilt from the recentred pose that does not move the pointer", lo=0.0, hi=45.0),
        "full_speed_deg": Param(25.0, doc="tilt at which the pointer reaches `max_speed_px_s`", lo=1.0, hi=90.0),
        "max_speed_px_s": Param(1200.0, doc="pointer speed at full tilt", lo=1.0, hi=100000.0),
        "exponent": Param(1.5, doc="response curve between dead zone and full tilt (1 = linear)", lo=0.5, hi=4.0),
    },
    "events": {
        "single_tap": Param("left_click", doc="action of a single tap", choices=ACTIONS),
        "double_tap": Param("double_click", doc="action of a double tap (`double_click` counts the single tap's click as "
                                 "the first one)", choices=ACTIONS),
        "free_fall": Param("next_mode", doc="action of a free fall (toss and catch)", choices=ACTIONS),
        "single_tap_wait_ms": Param(0, doc="hold a single tap's action this long and drop it if a double tap follows (use "
                                         "with `double_tap = \"right_click\"`); 0 = act at once", lo=0, hi=1000),
    },
    "freeze": {
        "tap_before_ms": Param(80, doc="pointer motion in this time before a tap is undone, so the click lands where the "
                                    "pointer was aimed before the knock jolted it", lo=0, hi=1000),
        "tap_after_ms": Param(150, doc="the pointer stays still this long after a tap", lo=0, hi=2000),
        "free_fall_before_ms": Param(400, doc="motion undone before a free fall (the toss)", lo=0, hi=3000),
        "free_fall_after_ms": Param(700, doc="the pointer stays still this long after a free fall (the catch)", lo=0, hi=5000),
    },
    "gyro": {
        "auto_bias": Param(True, doc="re-estimate the gyroscope bias on the host whenever the sphere lies still"),
        "still_dps": Param(3.0, doc="the sphere counts as still while every gyro axis stays within this of its mean", lo=0.01, hi=100.0),
        "still_time_s": Param(1.0, doc="how long it must be still for a bias update", lo=0.1, hi=30.0),
    },
    "orientation": {
        "source": Param("auto", doc="`host`: the host's fusion filter on RAW_SAMPLE; `device`: the firmware's ORIENTATION "
                             "packets; `auto` = host when raw samples arrive and sphere.fusion is installed", choices=("auto", "host", "device")),
        "use_mag": Param(False, doc="let the host filter use the magnetometer (needs a calibrated one; without it yaw "
                               "drifts slowly, which pointing does not mind)"),
        "filter": Param("auto", doc="host filter: `vqf` (the VQF library, Laidig & Seel 2023: the best on data nobody "
                             "tuned on, host/docs/fusion.md), `sphere` (sphere.fusion's SphereFilter), `madgwick`; "
                             "`auto` = vqf if installed (the daemon extra installs it), else sphere", choices=_host_filters),
        "beta": Param(0.1, doc="gain β (rad/s) of the host Madgwick filter", lo=0.0, hi=2.0),
    },
    "stream": {
        "enabled": Param(True, doc="serve orientation on a WebSocket and the 3-D page over HTTP"),
        "host": Param("127.0.0.1", doc="address to listen on (keep it local)"),
        "port": Param(8765, doc="TCP port of the WebSocket and the page (http://127.0.0.1:PORT/)", check=_port),
        "rate_hz": Param(60.0, doc="orientation messages per second", lo=1.0, hi=200.0),
        "smoothing": Param(_SMOOTHING, doc="smoothing filter of the streamed orientation, from the smoothing registry "
                                           "(its parameters in [smoothing.NAME], degrees); `none` = the orientation as "
                                           "measured", choices=_smoothing_names),
        "position_smoothing": Param(_POSITION_SMOOTHING, doc="smoothing filter of the streamed position (with a "
                                    "camera), its parameters in metres in [position_smoothing.NAME]; `none` = the "
                                    "hybrid tracker's estimate as it is", choices=lambda: tuple(_POSITION_FILTERS)),
        "max_clients": Param(16, doc="most WebSocket and page connections at once; more are refused (503)", lo=1, hi=1000),
    },
    "device": {
        "settings": Param([], doc="device settings sent to the sphere at every connect, as `sphere device set` takes "
                                  "them (`sphere device keys` lists them), e.g. [\"tap.threshold_g=2.5\", "
                                  "\"tap.axes=z\"]; they win over what the sphere saved (`sphere device save`), "
                                  "which it keeps for other programs; empty = the sphere's own", check=_device_settings),
    },
    "status": {
        "interval_s": Param(1.0, doc="how often the status line is refreshed", lo=0.05, hi=3600.0),
    },}

#: section → the check of keys that must agree (returns the reason, or None)
CORE_CHECKS = {"source": _check_source, "pointer": _check_pointer, "tilt": _check_tilt}


# ---- composing the sections ------------------------------------------------------------------------


class Section:
    """One section: its name, parameters, the check of keys that must agree, and the component it configures
    (None for the daemon's own)."""

    __slots__ = ("name", "params", "check", "component")

    def __init__(self, name: str, params: dict, check=None, component=None):
        self.name, self.params, self.check, self.component = name, params, check, component

    def defaults(self) -> Settings:
        return Settings(self.params, checked=True)


def registries() -> list[Registry]:
    """The registries of :data:`REGISTRIES`, imported."""
    return [load_object(spec) for spec in REGISTRIES]


def sections() -> dict[str, Section]:
    """Every section: the daemon's own and one per component that has parameters, in :data:`ORDER`."""
    found = {name: Section(name, params, CORE_CHECKS.get(name)) for name, params in CORE.items()}
    for registry in registries():
        for name in registry:
            try:
                cls = registry.load(name)
            except ModuleNotFoundError as e:  # a component whose optional library is missing: no section
                if e.name is None or e.name.startswith("sphere"):
                    raise
                continue
            params = getattr(cls, "PARAMS", None)
            if params:
                found[registry.section(name)] = Section(registry.section(name), params,
                                                        getattr(cls, "check_settings", None), cls)

    def key(name):
        top = name.split(".", 1)[0]
        return (ORDER.index(top) if top in ORDER else len(ORDER), top, "." in name)

    return {n: found[n] for n in sorted(found, key=key)}


# ---- values ---------------------------------------------------------------------------------------


class Config:
    """All settings; ``Config()`` is the defaults. ``values`` are already validated (``{section: {key: value}}``)."""

    def __init__(self, values: dict | None = None, origin: str = "defaults", _sections: dict | None = None):
        self.origin = origin
        self._specs = _sections if _sections is not None else sections()
        self._sections = {}
        values = values or {}
        for name, spec in self._specs.items():
            obj = Settings(spec.params, values.get(name, {}), checked=True)
            self._sections[name] = obj
            if "." not in name:
                setattr(self, name, obj)

    def __getitem__(self, name: str) -> Settings:
        return self._sections[name]

    def as_dict(self) -> dict:
        return {name: obj.as_dict() for name, obj in self._sections.items()}

    def with_overrides(self, overrides: dict, origin: str) -> "Config":
        """A copy with ``{section: {key: value}}`` validated and applied."""
        checked = validate(overrides, origin, together=False, known=self._specs)
        values = self.as_dict()
        for s, keys in checked.items():
            values[s].update(keys)
        return Config(values, origin=self.origin, _sections=self._specs)


def smoothing_params(cfg: Config, name: str, registry: Registry = _SMOOTHING_FILTERS) -> dict:
    """The ``[smoothing.NAME]`` values of a loaded config (none for a filter without parameters);
    ``registry=POSITION`` for ``[position_smoothing.NAME]``."""
    section = registry.section(name)
    return cfg[section].as_dict() if section in cfg._sections else {}


def default_path() -> Path:
    return paths.config_file()


def _suggest(word: str, options) -> str:
    close = difflib.get_close_matches(word, list(options), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def check_value(spec: Section, key: str, value, where: str):
    """The value converted to the key's type, or ConfigError saying what is wrong."""
    p = spec.params[key]
    try:
        return p.convert(value)
    except ParamError as e:
        hint = ""
        choices = p.allowed()
        if choices is not None and isinstance(value, str) and str(e).startswith("must be one of"):
            hint = _suggest(value, choices)
        raise ConfigError(f"{where}: [{spec.name}] {key} = {value!r}: {e}{hint}") from None


def flatten(values: dict, where: str, known: dict | None = None) -> dict:
    """``{"smoothing": {"tremor": {...}}}`` (nested TOML tables) → ``{"smoothing.tremor": {...}}``."""
    known = known if known is not None else sections()
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


def validate(values: dict, where: str, together: bool = True, known: dict | None = None) -> dict:
    """Check a ``{section: {key: value}}`` mapping (nested or dotted section names); returns the converted
    values with dotted section names."""
    known = known if known is not None else sections()
    out: dict[str, dict] = {}
    for name, keys in flatten(values, where, known).items():
        spec = known[name]
        for key, value in keys.items():
            if key not in spec.params and (name, key) in MOVED_KEYS:
                raise ConfigError(f"{where}: [{name}] {key} {MOVED_KEYS[name, key]}")
            if key not in spec.params:
                raise ConfigError(f"{where}: unknown key [{name}] {key}{_suggest(key, spec.params)}; keys of "
                                  f"[{name}] are {', '.join(spec.params)}")
            out.setdefault(name, {})[key] = check_value(spec, key, value, where)
    if together:
        for name, keys in out.items():
            spec = known[name]
            if spec.check is not None and keys:
                reason = spec.check(Settings(spec.params, keys, checked=True))
                if reason:
                    raise ConfigError(f"{where}: [{name}] {reason}")
    return out


def check_config(cfg: Config, where: str) -> None:
    """The cross-key checks on a whole Config (a key from the file with another one's default)."""
    for name, spec in cfg._specs.items():
        reason = spec.check(cfg[name]) if spec.check is not None else None
        if reason:
            raise ConfigError(f"{where}: [{name}] {reason}")


def load(path: Path | str | None = None, required: bool = False) -> Config:
    """Read and validate a config file. A missing default file means defaults; a missing named one is an error."""
    explicit = path is not None
    path = Path(path) if explicit else default_path()
    try:
        data = paths.read_config(path, explicit=explicit or required)
    except paths.ConfigFileError as e:
        raise ConfigError(str(e)) from None
    if not data and not path.exists():
        return Config()
    known = sections()
    checked = validate(data, str(path), known=known)
    cfg = Config(checked, origin=str(path), _sections=known)
    check_config(cfg, str(path))  # relations between keys: one key in the file, the other a default
    return cfg


def parse_set(items: list[str]) -> dict:
    """``["pointer.axes=local", "smoothing.tremor.notch_hz=9"]`` → ``{section: {key: value}}``, values
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


def shown(value) -> str:
    """A value as TOML writes it."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, list):
        return "[" + ", ".join(f'"{v}"' for v in value) + "]"
    return repr(value)


def markdown() -> str:
    """The key reference, as a Markdown table per section."""
    lines = []
    for name, spec in sections().items():
        lines += [f"### [{name}]", "", "| key | default | meaning |", "|---|---|---|"]
        for key, p in spec.params.items():
            doc = p.describe().replace("|", "\\|")
            choices = p.allowed()
            if choices and "`" not in doc:
                doc += " (" + ", ".join(f"`{c}`" for c in choices) + ")"
            lines.append(f"| `{key}` | `{shown(p.default)}` | {doc} |")
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover
    if "--markdown" in sys.argv:
        # run as __main__, this file is a second module: the real one holds the registries' PARTS
        from sphere.daemon import config as _config

        print(_config.markdown())
