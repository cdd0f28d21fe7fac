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
from sphere.daemon.backends import REGISTRY as _BACKENDS
from sphere.daemon.sources import PARAMS as _SOURCE_PARAMS
from sphere.errors import SphereError
from sphere.fusion.registry import live_available
from sphere.settings import Param, ParamError, Registry, Settings
from sphere.settings import load as load_object
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
    "device": "sphere.daemon.sources.serial:DeviceSettings",  # [device]: settings sent to the sphere at connect
    "pointer": "sphere.daemon.pointer:PointerMapper",  # [pointer]: rotation → pointer motion
    "tilt": "sphere.daemon.pointer:TiltMapper",  # [tilt]: tilt → pointer speed
    "camera": "sphere.camera.daemon_source:CameraPosition",  # a webcam or video file giving the ball's position
    "paths": "sphere.daemon.paths_config:PathsSettings",  # [paths] (read by sphere.paths)
    "gyro_bias": "sphere.daemon.gyro_bias:GyroBias",  # the host's one gyro-bias estimate (its [gyro] keys stay there)
    "rest_hold": "sphere.daemon.gyro_bias:RestHold",  # the pointer held while the sphere lies still
    "priority": "sphere.daemon.priority:LoopPriority",  # the port -> pointer loop's scheduling priority
}, section="{name}")

#: Every registry whose components have a section of their own: "module:attribute" of a
#: :class:`sphere.settings.Registry`, imported when the sections are first composed.
REGISTRIES: tuple[str, ...] = (
    "sphere.daemon.sources:REGISTRY",  # [source.NAME]
    "sphere.daemon.backends:REGISTRY",  # [backend.NAME]
    "sphere.daemon.outputs:REGISTRY",  # [outputs.NAME]
    "sphere.fusion.registry:REGISTRY",  # [orientation.NAME] (the filters the daemon can run: LIVE)
    "sphere.smoothing.registry:REGISTRY",  # [smoothing.NAME]
    "sphere.smoothing.registry:POSITION",  # [position_smoothing.NAME]
    "sphere.daemon.config:PARTS",  # [pointer], [tilt], [gyro], [device], [camera], [paths]
)

#: The sections in the order the reference lists them (by their first part; others follow).
ORDER = ("source", "output", "backend", "mode", "pointer", "tilt", "events", "freeze", "gyro", "gyro_bias",
         "rest_hold", "orientation", "stream", "device", "status", "priority", "outputs", "smoothing", "position_smoothing",
         "paths", "camera")

#: Keys of earlier releases that live elsewhere now: (section, key) -> what to write instead.
MOVED_KEYS = {
    ("pointer", "smoothing_dps"): "moved to [smoothing.tiered] smoothing_dps (the old smoothing is the filter "
                                  "`tiered`: [pointer] smoothing = \"tiered\"; the default is now `tremor`)",
    ("pointer", "smoothing_time_s"): "moved to [smoothing.tiered] smoothing_time_s (the old smoothing is the "
                                     "filter `tiered`: [pointer] smoothing = \"tiered\"; the default is now `tremor`)",
}

#: Keys of earlier releases that are read in their new place: (section, key) -> (section, key). A file that
#: still has them loads, with one note a line saying what to rename.
RENAMED = {
    **{("source", key): ("source.serial", key) for key in (
        "port", "candidates", "usb_ids", "baud", "reset_on_open", "low_latency", "baud_switch", "hello_timeout_s",
        "discovery_timeout_s", "link_timeout_s")},
    ("source", "replay"): ("source.replay", "file"),
    ("source", "speed"): ("source.replay", "speed"),
    ("source", "hid_vendor_id"): ("source.hid", "vendor_id"),
    ("source", "hid_product_id"): ("source.hid", "product_id"),
    ("source", "hid_product"): ("source.hid", "product"),
    ("source", "sim_seconds"): ("source.simulate", "seconds"),
    ("source", "sim_trace"): ("source.simulate", "trace"),
    ("output", "display"): ("backend.x11", "display"),
    ("orientation", "beta"): ("orientation.madgwick", "beta"),
    **{("stream", key): ("outputs.page", key) for key in ("enabled", "host", "port", "rate_hz", "max_clients")},
}


class ConfigError(SphereError):
    """A config file, override or flag that cannot be used; the message says which and why. ``section`` and
    ``key`` say where in a file (:func:`load` adds the line)."""

    def __init__(self, msg: str, section: str | None = None, key: str | None = None):
        super().__init__(msg)
        self.section, self.key = section, key


# ---- checks a range cannot say -------------------------------------------------------------------


def _modes_list(v):
    if not v:
        return "must name at least one mode"
    bad = [m for m in v if m not in MODES]
    if bad:
        return f"has unknown mode(s) {bad}; modes are {list(MODES)}"
    return None


def _smoothing_names():
    return tuple(_SMOOTHING_FILTERS)


def _backends():
    return ("auto", *_BACKENDS)


def _host_filters():
    """``auto`` and the filters the fusion registry marks live (read when asked: it imports their modules)."""
    return ("auto", *live_available())


# ---- the daemon's own sections ---------------------------------------------------------------------

#: section → its parameters
CORE: dict[str, dict[str, Param]] = {
    "source": _SOURCE_PARAMS,
    "output": {
        "backend": Param("auto", doc="where pointer motion goes, a backend of the registry: `uinput` (Linux, X11 and "
                                     "Wayland), `x11` (XTest; its display in [backend.x11]), `pynput` (macOS, "
                                     "Windows), `log` (print only); `auto` tries them in that order and falls back to "
                                     "log, saying why", choices=_backends),
        "screen_width_px": Param(0, doc="screen width used to turn degrees into pixels; 0 = ask the backend (x11, "
                                        "pynput; uinput asks the X display if there is one), else 1920", lo=0,
                                 hi=100000),
    },
    "mode": {
        "start": Param("pointer", doc="mode at start", choices=MODES),
        "cycle": Param(["pointer", "tilt", "3d"], doc="modes that `next_mode` steps through, in order",
            check=_modes_list),
    },
    "events": {
        "single_tap": Param("left_click", doc="action of a single tap", choices=ACTIONS),
        "double_tap": Param("double_click", doc="action of a double tap (`double_click` counts the single tap's "
                                                "click as the first one)", choices=ACTIONS),
        "free_fall": Param("next_mode", doc="action of a free fall (toss and catch)", choices=ACTIONS),
        "single_tap_wait_ms": Param(0, doc="hold a single tap's action this long and drop it if a double tap follows "
                                           "(use with `double_tap = \"right_click\"`); 0 = act at once", lo=0, hi=1000),
    },
    "freeze": {
        "tap_before_ms": Param(80, doc="pointer motion in this time before a tap is undone, so the click lands where "
                                       "the pointer was aimed before the knock jolted it", lo=0, hi=1000),
        "tap_after_ms": Param(150, doc="the pointer stays still this long after a tap", lo=0, hi=2000),
        "free_fall_before_ms": Param(400, doc="motion undone before a free fall (the toss)", lo=0, hi=3000),
        "free_fall_after_ms": Param(700, doc="the pointer stays still this long after a free fall (the catch)",
            lo=0, hi=5000),
    },
    "gyro": {
        "auto_bias": Param(True, doc="re-estimate the gyroscope bias on the host whenever the sphere lies still"),
        "still_dps": Param(3.0, doc="the sphere counts as still while every gyro axis stays within this of its mean",
                           lo=0.01, hi=100.0),
        "still_time_s": Param(1.0, doc="how long it must be still for a bias update", lo=0.1, hi=30.0),
    },
    "orientation": {
        "source": Param("auto", doc="`host`: the host's fusion filter on RAW_SAMPLE; `device`: the firmware's "
                                    "ORIENTATION packets; `auto` = host when raw samples arrive and sphere.fusion is "
                                    "installed", choices=("auto", "host", "device")),
        "use_mag": Param(False, doc="let the host filter use the magnetometer (needs a calibrated one; without it yaw "
                               "drifts slowly, which pointing does not mind)"),
        "filter": Param("auto", doc="host filter: `sphere` (sphere.fusion's SphereFilter: the best on data nobody "
                                    "tuned it on, host/docs/fusion.md), `vqf` (the VQF library, Laidig & Seel 2023; "
                                    "the daemon extra installs it), `madgwick`; `auto` = sphere (each with its "
                                    "parameters in [orientation.NAME])", choices=_host_filters),
    },
    "stream": {
        "smoothing": Param(_SMOOTHING, doc="smoothing filter of the orientation every output gets (the 3-D page, "
                                           "OpenTrack …), from the smoothing registry (its parameters in "
                                           "[smoothing.NAME], degrees); `none` = the orientation as measured",
                           choices=_smoothing_names),
        "position_smoothing": Param(_POSITION_SMOOTHING, doc="smoothing filter of the position every output gets "
                                                             "(with a camera), its parameters in metres in "
                                                             "[position_smoothing.NAME]; `none` = the hybrid "
                                                             "tracker's estimate as it is",
            choices=lambda: tuple(_POSITION_FILTERS)),
    },
    "status": {
        "interval_s": Param(1.0, doc="how often the status line is refreshed", lo=0.05, hi=3600.0),
    },}

#: section → the check of keys that must agree (returns the reason, or None)
CORE_CHECKS: dict = {}


def _check_replay(cfg):
    if cfg.source.kind == "replay" and not cfg["source.replay"].file:
        return '[source] kind = "replay" needs a capture file: --replay FILE or [source.replay] file = "FILE"'
    return None


#: checks of keys in different sections, on the whole Config (return the reason, or None)
WHOLE_CHECKS = (_check_replay,)


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
            if params and getattr(cls, "LIVE", True):  # an orientation filter the daemon cannot run: none
                found[registry.section(name)] = Section(registry.section(name), params,
                                                        getattr(cls, "check_settings", None), cls)

    def key(name):
        top = name.split(".", 1)[0]
        return (ORDER.index(top) if top in ORDER else len(ORDER), top, "." in name)

    return {n: found[n] for n in sorted(found, key=key)}


# ---- values ---------------------------------------------------------------------------------------


class Config:
    """All settings; ``Config()`` is the defaults. ``values`` are already validated (``{section: {key: value}}``)."""

    def __init__(self, values: dict | None = None, origin: str = "defaults", _sections: dict | None = None,
                 notes: list | None = None):
        self.origin = origin
        #: what the user should change in the file (old key names read in their new place), one line each
        self.notes = list(notes or [])
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

    def __contains__(self, name: str) -> bool:
        return name in self._sections

    def get(self, name: str) -> Settings | None:
        """A section's settings, or None for a component without parameters (it has no section)."""
        return self._sections.get(name)

    def as_dict(self) -> dict:
        return {name: obj.as_dict() for name, obj in self._sections.items()}

    def with_overrides(self, overrides: dict, origin: str) -> "Config":
        """A copy with ``{section: {key: value}}`` validated and applied."""
        notes = list(self.notes)
        checked = validate(overrides, origin, together=False, known=self._specs, notes=notes)
        values = self.as_dict()
        for s, keys in checked.items():
            values[s].update(keys)
        return Config(values, origin=self.origin, _sections=self._specs, notes=notes)


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
        raise ConfigError(f"{where}: [{spec.name}] {key} = {value!r}: {e}{hint}", spec.name, key) from None


def flatten(values: dict, where: str, known: dict | None = None) -> dict:
    """``{"smoothing": {"tremor": {...}}}`` (nested TOML tables) → ``{"smoothing.tremor": {...}}``."""
    known = known if known is not None else sections()
    prefixes = {n.rsplit(".", 1)[0] for n in known if "." in n}
    out: dict[str, dict] = {}

    def walk(name, table):
        if not isinstance(table, dict):
            raise ConfigError(f"{where}: {name} must be a [{name}] table, not a value",
                              *(name.rsplit(".", 1) if "." in name else ("", name)))
        for key, value in table.items():
            sub = f"{name}.{key}"
            if isinstance(value, dict) and (sub in known or sub in prefixes):
                walk(sub, value)
            elif name in known:
                out.setdefault(name, {})[key] = value
            else:
                raise ConfigError(f"{where}: unknown section [{sub if isinstance(value, dict) else name}]"
                                  f"{_suggest(sub, known)}; sections are {', '.join(known)}",
                                  *((sub, None) if isinstance(value, dict) else (name, key)))
        if name in known:
            out.setdefault(name, {})

    for name, table in values.items():
        if name not in known and name not in prefixes:
            raise ConfigError(f"{where}: unknown section [{name}]{_suggest(name, known)}; sections are "
                              f"{', '.join(known)}", name)
        walk(name, table)
    return out


def validate(values: dict, where: str, together: bool = True, known: dict | None = None,
             notes: list | None = None) -> dict:
    """Check a ``{section: {key: value}}`` mapping (nested or dotted section names); returns the converted
    values with dotted section names. A key of :data:`RENAMED` is read in its new place, with a line in
    ``notes`` saying what to rename."""
    known = known if known is not None else sections()
    out: dict[str, dict] = {}
    for name, keys in flatten(values, where, known).items():
        spec = known[name]
        for key, value in keys.items():
            if key not in spec.params and (name, key) in MOVED_KEYS:
                raise ConfigError(f"{where}: [{name}] {key} {MOVED_KEYS[name, key]}", name, key)
            if key not in spec.params and (name, key) in RENAMED and RENAMED[name, key][0] in known:
                new_name, new_key = RENAMED[name, key]
                if notes is not None:
                    notes.append(f"{where}: [{name}] {key} is now [{new_name}] {new_key} (read as that; rename it "
                                 "there)")
                out.setdefault(new_name, {})[new_key] = check_value(known[new_name], new_key, value, where)
                continue
            if key not in spec.params:
                raise ConfigError(f"{where}: unknown key [{name}] {key}{_suggest(key, spec.params)}; keys of "
                                  f"[{name}] are {', '.join(spec.params)}", name, key)
            out.setdefault(name, {})[key] = check_value(spec, key, value, where)
    if together:
        for name, keys in out.items():
            spec = known[name]
            if spec.check is not None and keys:
                reason = spec.check(Settings(spec.params, keys, checked=True))
                if reason:
                    raise ConfigError(f"{where}: [{name}] {reason}", name)
    return out


def check_config(cfg: Config, where: str) -> None:
    """The cross-key checks on a whole Config (a key from the file with another one's default)."""
    for name, spec in cfg._specs.items():
        reason = spec.check(cfg[name]) if spec.check is not None else None
        if reason:
            raise ConfigError(f"{where}: [{name}] {reason}")
    for check in WHOLE_CHECKS:
        reason = check(cfg)
        if reason:
            raise ConfigError(f"{where}: {reason}")


def line_of(text: str, section: str | None, key: str | None = None) -> int | None:
    """The line (from 1) of a config file's text that sets ``[section] key`` (``section`` "" for a top-level key;
    ``key`` None: the section's header), for a message that points at it; None when no line plainly does (a
    key set through an inline table)."""
    def dotted(name: str) -> str:  # ' "outputs" . osc ' -> 'outputs.osc'
        return ".".join(part.strip().strip('"\'') for part in name.split("."))

    want = ".".join(n for n in (section, key) if n)
    table = ""
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if line.startswith("[") and not line.startswith("[["):  # a [table] header (an array of tables: not ours)
            table = dotted(line.split("#")[0].strip().strip("[]"))
            if key is None and table == want:
                return n
        elif key is not None and "=" in line and not line.startswith("#"):
            lhs = dotted(line.split("=", 1)[0])
            if (f"{table}.{lhs}" if table else lhs) == want:
                return n
    return None


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
    notes: list[str] = []
    try:
        checked = validate(data, str(path), known=known, notes=notes)
    except ConfigError as e:  # where in the file: path:LINE
        line = line_of(path.read_text(encoding="utf-8"), e.section, e.key) if e.section is not None else None
        if line is None:
            raise
        raise ConfigError(f"{path}:{line}:{str(e)[len(str(path)) + 1:]}", e.section, e.key) from None
    cfg = Config(checked, origin=str(path), _sections=known, notes=notes)
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
