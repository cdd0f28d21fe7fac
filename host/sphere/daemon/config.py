"""sphere-mouse settings: every key, its default, its unit and its check, in one table.

The same table validates ``~/.config/sphere-mouse/config.toml``, the ``--set SECTION.KEY=VALUE``
overrides and the command-line flags, and writes the key reference in host/docs/sphere-mouse.md
(``python -m sphere.daemon.config --markdown``). A bad key or value stops the daemon at start with a
message that names the file, the key, what was given and what is allowed.
"""

from __future__ import annotations

import difflib
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

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


class ConfigError(Exception):
    """A config file, override or flag that cannot be used; the message says which and why."""


@dataclass(frozen=True)
class Option:
    default: Any
    kind: type | tuple
    doc: str
    check: Callable[[Any], str | None] | None = None  # returns the reason a value is bad, or None
    choices: tuple | None = None


def _positive(v):
    return None if v > 0 else "must be greater than 0"


def _non_negative(v):
    return None if v >= 0 else "must be 0 or more"


def _range(lo, hi):
    def check(v):
        return None if lo <= v <= hi else f"must be between {lo} and {hi}"

    return check


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


_num = (int, float)

SCHEMA: dict[str, dict[str, Option]] = {
    "source": {
        "kind": Option("auto", str, "where frames come from: `serial`, `hid`, `replay`, `simulate`; `auto` = serial "
                       "(with discovery), or `replay`/`simulate` when those flags are given",
                       choices=("auto", "serial", "hid", "replay", "simulate")),
        "port": Option("auto", str, "serial port (`/dev/ttyUSB0`, `/dev/rfcomm0`, `/dev/sphere`); `auto` tries every "
                       "candidate port and keeps the one that answers with a HELLO"),
        "candidates": Option(["/dev/sphere", "/dev/ttyUSB*", "/dev/ttyACM*", "/dev/rfcomm*"], list,
                             "glob patterns of ports that `port = \"auto\"` tries, in order", _str_list),
        "baud": Option(115200, int, "baud rate (the Nano's default; an HC-05/HC-06 must be set to the same)", _positive),
        "reset_on_open": Option(True, bool, "let opening the port reset a USB Nano through DTR (its HELLO then "
                                "arrives after the bootloader, ~1–2 s); false holds DTR low after opening"),
        "hello_timeout_s": Option(0.5, _num, "after opening a port, send GET_HELLO if no HELLO came within this "
                                  "time (Bluetooth links do not reset the board)", _positive),
        "discovery_timeout_s": Option(3.0, _num, "give up on a candidate port that sent no HELLO within this time",
                                      _positive),
        "link_timeout_s": Option(2.0, _num, "a connected port that delivers no byte for this long is taken as "
                                 "lost (a Bluetooth link that dropped) and reopened", _positive),
        "reconnect_interval_s": Option(1.0, _num, "pause between attempts to find the sphere again", _positive),
        "replay": Option("", str, "capture file to replay (same as `--replay`)"),
        "speed": Option(1.0, _num, "replay speed: 1 = as recorded, 4 = four times faster, 0 = as fast as possible",
                        _non_negative),
        "hid_vendor_id": Option(0, int, "USB vendor ID of a HID receiver (0 = any device whose product string "
                                "contains `hid_product`)", _range(0, 0xFFFF)),
        "hid_product_id": Option(0, int, "USB product ID of a HID receiver (0 = any)", _range(0, 0xFFFF)),
        "hid_product": Option("sphere", str, "substring of the HID product string looked for when no IDs are set"),
        "sim_seconds": Option(600.0, _num, "how long the virtual board runs with `--simulate` (the daemon ends with "
                              "it)", _range(1.0, 86400.0)),
        "sim_trace": Option("", str, "motion the virtual board plays with `--simulate`: a BROAD trial (.mat, name or "
                            "number) or `synthetic:NAME` (see `sphere sim --help`); empty = `synthetic:rotation:15`"),
    },
    "output": {
        "backend": Option("auto", str, "`uinput` (Linux, X11 and Wayland), `x11` (XTest), `pynput` (macOS, Windows), "
                          "`log` (print only); `auto` tries uinput, x11, pynput, then falls back to log and says why",
                          choices=("auto", "uinput", "x11", "pynput", "log")),
        "display": Option("", str, "X display for the x11 backend (empty = `$DISPLAY`)"),
        "screen_width_px": Option(0, int, "screen width used to turn degrees into pixels; 0 = ask the backend "
                                  "(x11, pynput; uinput asks the X display if there is one), else 1920", _non_negative),
    },
    "mode": {
        "start": Option("pointer", str, "mode at start", choices=MODES),
        "cycle": Option(["pointer", "tilt", "3d"], list, "modes that `next_mode` steps through, in order",
                        _modes_list),
    },
    "pointer": {
        "slow_deg_per_width": Option(40.0, _num, "degrees of wrist rotation that move the pointer one screen width "
                                     "when turning slowly (below `accel_low_dps`)", _positive),
        "fast_deg_per_width": Option(40.0, _num, "the same when turning fast (above `accel_high_dps`); smaller than "
                                     "`slow_deg_per_width` = acceleration; equal = none", _positive),
        "accel_low_dps": Option(20.0, _num, "rotation speed (°/s) up to which the slow sensitivity applies",
                                _non_negative),
        "accel_high_dps": Option(120.0, _num, "rotation speed (°/s) from which the fast sensitivity applies; "
                                 "between the two it is blended linearly", _positive),
        "tightening_dps": Option(1.0, _num, "rotations slower than this are scaled down in proportion to their "
                                 "speed (soft, instead of a dead zone that swallows them); 0 = off", _non_negative),
        "smoothing_dps": Option(8.0, _num, "rotations slower than this are smoothed (fully below half of it), "
                                "faster ones pass unsmoothed; 0 = off", _non_negative),
        "smoothing_time_s": Option(0.06, _num, "averaging window of the smoothing", _range(0.005, 1.0)),
        "axes": Option("world", str, "`world`: turning about the vertical moves the pointer sideways however the "
                       "sphere is rolled (uses gravity); `local`: the sensor's own z (yaw) and y (pitch) axes",
                       choices=("world", "local")),
        "invert_x": Option(False, bool, "swap left and right"),
        "invert_y": Option(False, bool, "swap up and down"),
    },
    "tilt": {
        "dead_zone_deg": Option(3.0, _num, "tilt from the recentred pose that does not move the pointer",
                                _range(0.0, 45.0)),
        "full_speed_deg": Option(25.0, _num, "tilt at which the pointer reaches `max_speed_px_s`", _range(1.0, 90.0)),
        "max_speed_px_s": Option(1200.0, _num, "pointer speed at full tilt", _positive),
        "exponent": Option(1.5, _num, "response curve between dead zone and full tilt (1 = linear)", _range(0.5, 4.0)),
    },
    "events": {
        "single_tap": Option("left_click", str, "action of a single tap", choices=ACTIONS),
        "double_tap": Option("double_click", str, "action of a double tap (`double_click` counts the single tap's "
                             "click as the first one)", choices=ACTIONS),
        "free_fall": Option("next_mode", str, "action of a free fall (toss and catch)", choices=ACTIONS),
        "single_tap_wait_ms": Option(0, int, "hold a single tap's action this long and drop it if a double tap "
                                     "follows (use with `double_tap = \"right_click\"`); 0 = act at once",
                                     _range(0, 1000)),
    },
    "freeze": {
        "tap_before_ms": Option(80, int, "pointer motion in this time before a tap is undone, so the click lands "
                                "where the pointer was aimed before the knock jolted it", _range(0, 1000)),
        "tap_after_ms": Option(150, int, "the pointer stays still this long after a tap", _range(0, 2000)),
        "free_fall_before_ms": Option(400, int, "motion undone before a free fall (the toss)", _range(0, 3000)),
        "free_fall_after_ms": Option(700, int, "the pointer stays still this long after a free fall (the catch)",
                                     _range(0, 5000)),
    },
    "gyro": {
        "auto_bias": Option(True, bool, "re-estimate the gyroscope bias on the host whenever the sphere lies still"),
        "still_dps": Option(3.0, _num, "the sphere counts as still while every gyro axis stays within this of its "
                            "mean", _positive),
        "still_time_s": Option(1.0, _num, "how long it must be still for a bias update", _range(0.1, 30.0)),
    },
    "orientation": {
        "source": Option("auto", str, "`host`: the host's fusion filter on RAW_SAMPLE; `device`: the firmware's "
                         "ORIENTATION packets; `auto` = host when raw samples arrive and sphere.fusion is installed",
                         choices=("auto", "host", "device")),
        "use_mag": Option(False, bool, "let the host filter use the magnetometer (needs a calibrated one; "
                          "without it yaw drifts slowly, which pointing does not mind)"),
        "filter": Option("auto", str, "host filter: `sphere` (sphere.fusion's SphereFilter: rejects taps, vibration "
                         "and hand acceleration, learns the gyro bias at rest), `madgwick`; `auto` = the best installed",
                         choices=("auto", "sphere", "madgwick")),
        "beta": Option(0.1, _num, "gain β (rad/s) of the host Madgwick filter", _range(0.0, 2.0)),
    },
    "stream": {
        "enabled": Option(True, bool, "serve orientation on a WebSocket and the 3-D page over HTTP"),
        "host": Option("127.0.0.1", str, "address to listen on (keep it local)"),
        "port": Option(8765, int, "TCP port of the WebSocket and the page (http://127.0.0.1:PORT/)", _port),
        "rate_hz": Option(60.0, _num, "orientation messages per second", _range(1.0, 200.0)),
    },
    "status": {
        "interval_s": Option(1.0, _num, "how often the status line is refreshed", _positive),
    },
}


class Section:
    """One section's values as attributes (``cfg.pointer.slow_deg_per_width``)."""

    def __init__(self, name: str, values: dict):
        self._name = name
        self.__dict__.update(values)

    def as_dict(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if not k.startswith("_")}

    def __repr__(self):
        return f"Section({self._name}, {self.as_dict()})"


class Config:
    """All settings; ``Config()`` is the defaults."""

    def __init__(self, values: dict | None = None, origin: str = "defaults"):
        self.origin = origin
        merged = {s: {k: _copy(o.default) for k, o in opts.items()} for s, opts in SCHEMA.items()}
        for section, keys in (values or {}).items():
            merged[section].update(keys)
        for section, keys in merged.items():
            setattr(self, section, Section(section, keys))

    def as_dict(self) -> dict:
        return {s: getattr(self, s).as_dict() for s in SCHEMA}

    def with_overrides(self, overrides: dict, origin: str) -> "Config":
        """A copy with ``{section: {key: value}}`` validated and applied."""
        checked = validate(overrides, origin)
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
    if kind is _num:
        return "a number"
    return {bool: "true or false", int: "an integer", str: "a string", list: "a list"}.get(kind, str(kind))


def check_value(section: str, key: str, value, where: str):
    """The value converted to the option's type, or ConfigError saying what is wrong."""
    opt = SCHEMA[section][key]
    label = f"{where}: [{section}] {key} = {value!r}"
    kind = opt.kind
    if kind is _num:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        if ok:
            value = float(value)
    elif kind is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
    else:
        ok = isinstance(value, kind)
    if not ok:
        raise ConfigError(f"{label}: must be {_type_name(kind)}. {opt.doc}")
    if opt.choices is not None and value not in opt.choices:
        raise ConfigError(f"{label}: must be one of {', '.join(map(repr, opt.choices))}{_suggest(str(value), opt.choices)}")
    if opt.check is not None:
        reason = opt.check(value)
        if reason:
            raise ConfigError(f"{label}: {reason}")
    return value


def validate(values: dict, where: str) -> dict:
    """Check a ``{section: {key: value}}`` mapping against SCHEMA; returns the converted values."""
    out: dict[str, dict] = {}
    for section, keys in values.items():
        if section not in SCHEMA:
            raise ConfigError(f"{where}: unknown section [{section}]{_suggest(section, SCHEMA)}; sections are "
                              f"{', '.join(SCHEMA)}")
        if not isinstance(keys, dict):
            raise ConfigError(f"{where}: {section} must be a [{section}] table, not a value")
        for key, value in keys.items():
            if key not in SCHEMA[section]:
                raise ConfigError(f"{where}: unknown key [{section}] {key}{_suggest(key, SCHEMA[section])}; keys of "
                                  f"[{section}] are {', '.join(SCHEMA[section])}")
            out.setdefault(section, {})[key] = check_value(section, key, value, where)
    _check_together(out, where)
    return out


def _check_together(values: dict, where: str) -> None:
    p = values.get("pointer", {})
    lo, hi = p.get("accel_low_dps"), p.get("accel_high_dps")
    if lo is not None and hi is not None and hi <= lo:
        raise ConfigError(f"{where}: [pointer] accel_high_dps = {hi} must be greater than accel_low_dps = {lo}")
    t = values.get("tilt", {})
    dz, full = t.get("dead_zone_deg"), t.get("full_speed_deg")
    if dz is not None and full is not None and full <= dz:
        raise ConfigError(f"{where}: [tilt] full_speed_deg = {full} must be greater than dead_zone_deg = {dz}")


def load(path: Path | str | None = None, required: bool = False) -> Config:
    """Read and validate a config file. A missing default file means defaults; a missing named one is an error."""
    explicit = path is not None
    path = Path(path) if explicit else default_path()
    if not path.exists():
        if explicit or required:
            raise ConfigError(f"{path}: no such config file")
        return Config()
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML: {e}") from None
    except OSError as e:
        raise ConfigError(f"{path}: cannot read: {e.strerror}") from None
    checked = validate(data, str(path))
    cfg = Config(checked, origin=str(path))
    # relations between keys are checked on the merged result too (one key in the file, one default)
    _check_together(cfg.as_dict(), str(path))
    return cfg


def parse_set(items: list[str]) -> dict:
    """``["pointer.axes=local", "tilt.exponent=2"]`` → nested dict, values parsed as TOML values."""
    out: dict[str, dict] = {}
    for item in items:
        if "=" not in item or "." not in item.split("=", 1)[0]:
            raise ConfigError(f"--set {item!r}: expected SECTION.KEY=VALUE, e.g. pointer.axes=local")
        name, text = item.split("=", 1)
        section, key = name.strip().split(".", 1)
        try:
            value = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = text.strip()  # a bare word: take it as a string (pointer.axes=local)
        out.setdefault(section, {})[key] = value
    return out


def markdown() -> str:
    """The key reference, as a Markdown table per section."""
    lines = []
    for section, opts in SCHEMA.items():
        lines += [f"### [{section}]", "", "| key | default | meaning |", "|---|---|---|"]
        for key, o in opts.items():
            default = o.default
            if isinstance(default, bool):
                shown = "true" if default else "false"
            elif isinstance(default, str):
                shown = f'"{default}"'
            elif isinstance(default, list):
                shown = "[" + ", ".join(f'"{v}"' for v in default) + "]"
            else:
                shown = repr(default)
            doc = o.doc.replace("|", "\\|")
            if o.choices and "`" not in doc:
                doc += " (" + ", ".join(f"`{c}`" for c in o.choices) + ")"
            lines.append(f"| `{key}` | `{shown}` | {doc} |")
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover
    if "--markdown" in sys.argv:
        print(markdown())
