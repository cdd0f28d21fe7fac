"""The sphere's device settings by name, in physical units, turned into the commands of protocol/spec.md §5
(pure logic: no port). Used by ``sphere device``.

    plan = plan_settings(["tap.threshold_g=2.5", "stream.raw_rate_hz=100"], hello)
    for packet in plan.packets: ...        # SET_TAP, SET_STREAM: one command per group of keys
    plan.notes                             # what was filled in and why

A command sets every field of its group at once (SET_TAP has five); a key not given keeps what the device
reports: every setting through GET_SETTINGS (protocol 3, spec §5.3), the stream and the board in HELLO; an
older device cannot report the others, and they are sent as the firmware's default (firmware/src/core:
adxl345.cpp DEFAULT_TAP and DEFAULT_FREE_FALL, marg_filter.h DEFAULT_BETA_MILLI), which the notes say.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field

from sphere.errors import SphereError
from sphere.protocol.packets import (
    BOARD_PROFILES,
    SETTINGS_EEPROM_INVALID,
    SETTINGS_NONE_SAVED,
    SETTINGS_SAVED,
    STREAM_ORIENTATION,
    STREAM_RAW,
    STREAM_STATUS,
    SetBoard,
    SetFilter,
    SetFreeFall,
    SetStream,
    SetTap,
)

IMU_RATE_HZ = 200
#: Rates the firmware accepts: divisors of the 200 Hz sample clock (spec §5, SET_STREAM).
RATES_HZ = tuple(r for r in range(1, IMU_RATE_HZ + 1) if IMU_RATE_HZ % r == 0)


class SettingError(SphereError, ValueError):
    """A key or value that cannot be sent; the message says what is allowed."""


def _not_a_number(key: str, text: str, unit: str, what: str = "a number") -> str:
    """What is wrong with a value that is not a number: its unit written after it (the key names the unit), or
    anything else."""
    bare = text.strip()
    if unit and bare.lower().endswith(unit.lower()):
        bare = bare[: -len(unit)].strip()
        try:
            float(bare)
            return f"give the number alone, the key says the unit ({key}={bare})"
        except ValueError:
            pass
    return f"not {what}"


@dataclass(frozen=True)
class Setting:
    key: str
    group: str  # the command that carries it
    unit: str
    lsb: float | None  # physical units per LSB (None: not a scaled number)
    lo: int = 0  # LSB range
    hi: int = 255
    default_lsb: int | None = None  # the firmware's power-up value
    doc: str = ""

    def to_lsb(self, text: str) -> int:
        if self.lsb is None:
            raise AssertionError(self.key)
        try:
            value = float(text)
        except ValueError:
            raise SettingError(f"{self.key}={text}: {_not_a_number(self.key, text, self.unit)}; {self.describe()}") from None
        if not math.isfinite(value):
            raise SettingError(f"{self.key}={text}: not a number; {self.describe()}")
        n = round(value / self.lsb)
        if not self.lo <= n <= self.hi:
            raise SettingError(f"{self.key}={text}: out of range; {self.describe()}")
        return n

    def describe(self) -> str:
        if self.lsb is None:
            return self.doc
        lo, hi = self.lo * self.lsb, self.hi * self.lsb
        unit = f" {self.unit}" if self.unit else ""
        return f"{self.doc}: {lo:g} … {hi:g}{unit} in steps of {self.lsb:g}{unit}"

    def physical(self, lsb: int) -> str:
        return f"{lsb * self.lsb:g} {self.unit}".rstrip() if self.lsb is not None else str(lsb)


_TAP_DEFAULT = (48, 32, 80, 240, 7)  # adxl345.cpp DEFAULT_TAP: 3 g, 20 ms, 100 ms, 300 ms, x y z
_FF_DEFAULT = (7, 30)  # DEFAULT_FREE_FALL: 0.44 g for 150 ms
_BETA_DEFAULT = 41  # DEFAULT_BETA_MILLI

SETTINGS: dict[str, Setting] = {s.key: s for s in (
    Setting("tap.threshold_g", "tap", "g", 0.0625, 1, 255, _TAP_DEFAULT[0], "how hard a knock must be (THRESH_TAP)"),
    Setting("tap.duration_ms", "tap", "ms", 0.625, 1, 255, _TAP_DEFAULT[1], "longest a knock may last (DUR)"),
    Setting("tap.latency_ms", "tap", "ms", 1.25, 0, 255, _TAP_DEFAULT[2],
            "wait after a knock before a second may start (LATENT; 0 = no double tap)"),
    Setting("tap.window_ms", "tap", "ms", 1.25, 0, 255, _TAP_DEFAULT[3],
            "time in which the second knock of a double tap must come (WINDOW; 0 = no double tap)"),
    Setting("tap.axes", "tap", "", None, 0, 15, _TAP_DEFAULT[4],
            "axes that detect taps: letters from xyz (e.g. xyz, z), 'none', optionally '+suppress'"),
    Setting("free_fall.threshold_g", "free_fall", "g", 0.0625, 1, 255, _FF_DEFAULT[0],
            "below this acceleration the sphere is falling (THRESH_FF)"),
    Setting("free_fall.time_ms", "free_fall", "ms", 5.0, 1, 255, _FF_DEFAULT[1], "for at least this long (TIME_FF)"),
    Setting("stream.raw", "stream", "", None, 0, 1, 1, "RAW_SAMPLE packets: on or off"),
    Setting("stream.orientation", "stream", "", None, 0, 1, 1, "ORIENTATION packets: on or off"),
    Setting("stream.status", "stream", "", None, 0, 1, 1, "a STATUS packet once a second: on or off"),
    Setting("stream.raw_rate_hz", "stream", "Hz", None, 0, IMU_RATE_HZ, None,
            f"RAW_SAMPLE rate, a divisor of {IMU_RATE_HZ}: {', '.join(map(str, RATES_HZ))}"),
    Setting("stream.orientation_rate_hz", "stream", "Hz", None, 0, IMU_RATE_HZ, None,
            f"ORIENTATION rate, a divisor of {IMU_RATE_HZ}: {', '.join(map(str, RATES_HZ))}"),
    Setting("filter.beta", "filter", "", 0.001, 0, 2000, _BETA_DEFAULT, "the MARG filter's gain β"),
    Setting("board", "board", "", None, 0, max(BOARD_PROFILES), 0,
            "the board's axis maps (spec §4.2.1): " + ", ".join(BOARD_PROFILES.values())),
)}

GROUP_ORDER = ("board", "stream", "tap", "free_fall", "filter")
_ON = {"on": 1, "true": 1, "1": 1, "yes": 1, "off": 0, "false": 0, "0": 0, "no": 0}


def _axes_bits(text: str) -> int:
    t = text.strip().lower()
    suppress = t.endswith("+suppress")
    if suppress:
        t = t[: -len("+suppress")]
    if t == "none":
        bits = 0
    else:
        if not t or any(c not in "xyz" for c in t) or len(set(t)) != len(t):
            raise SettingError(f"tap.axes={text}: {SETTINGS['tap.axes'].doc}")
        bits = sum({"x": 4, "y": 2, "z": 1}[c] for c in t)
    return bits | (8 if suppress else 0)


def axes_text(bits: int) -> str:
    letters = "".join(c for c, b in (("x", 4), ("y", 2), ("z", 1)) if bits & b) or "none"
    return letters + ("+suppress" if bits & 8 else "")


def _suggest(key: str) -> str:
    close = difflib.get_close_matches(key, SETTINGS, n=1)
    return f" (did you mean {close[0]}?)" if close else ""


def parse_assignment(item: str) -> tuple[str, int]:
    """``KEY=VALUE`` → (key, value in LSB / code)."""
    if "=" not in item:
        raise SettingError(f"{item!r}: expected KEY=VALUE, e.g. tap.threshold_g=2.5 (`sphere device keys` lists them)")
    key, text = (s.strip() for s in item.split("=", 1))
    if not key:
        raise SettingError(f"{item!r}: no KEY before '=', e.g. tap.threshold_g=2.5 (`sphere device keys` lists them)")
    s = SETTINGS.get(key)
    if s is None:
        raise SettingError(f"{key}: no such setting{_suggest(key)}; `sphere device keys` lists them")
    if key == "tap.axes":
        return key, _axes_bits(text)
    if key in ("stream.raw", "stream.orientation", "stream.status"):
        if text.lower() not in _ON:
            raise SettingError(f"{key}={text}: on or off")
        return key, _ON[text.lower()]
    if key.endswith("_rate_hz"):
        try:
            rate = int(text)
        except ValueError:
            raise SettingError(f"{key}={text}: {_not_a_number(key, text, s.unit, 'a whole number')}; {s.doc}") from None
        if rate not in RATES_HZ:
            raise SettingError(f"{key}={text}: {s.doc}")
        return key, rate
    if key == "board":
        names = {v: k for k, v in BOARD_PROFILES.items()}
        if text not in names:
            raise SettingError(f"board={text}: one of {', '.join(names)}")
        return key, names[text]
    return key, s.to_lsb(text)


def current_from_settings(packets) -> dict[str, int]:
    """Every key but ``board`` from GET_SETTINGS's block (spec §5.3), as the four commands it is made of
    (``Reply.settings()``)."""
    stream, tap, free_fall, beta = packets
    mode = stream.stream_mode
    return {"stream.raw": mode & 1, "stream.orientation": mode >> 1 & 1, "stream.status": mode >> 2 & 1,
            "stream.raw_rate_hz": stream.raw_rate_hz, "stream.orientation_rate_hz": stream.orientation_rate_hz,
            "tap.threshold_g": tap.thresh_tap, "tap.duration_ms": tap.dur, "tap.latency_ms": tap.latent,
            "tap.window_ms": tap.window, "tap.axes": tap.tap_axes,
            "free_fall.threshold_g": free_fall.thresh_ff, "free_fall.time_ms": free_fall.time_ff,
            "filter.beta": beta.beta}


def settings_state_text(state: int) -> str:
    """What GET_SETTINGS's settings_state means for the user (spec §5.3)."""
    if state & SETTINGS_EEPROM_INVALID:
        return ("the settings saved on the sphere were damaged (version or CRC wrong, or a value out of range): "
                "it uses its defaults; set them again and `sphere device save`")
    if state & SETTINGS_SAVED:
        return "these are the settings saved on the sphere: it starts with them at every power-up"
    if state & SETTINGS_NONE_SAVED:
        return "nothing saved: the sphere starts with its defaults; `sphere device save` keeps these"
    return "changed since they were saved: `sphere device save` keeps them, else the saved ones come back at power-up"


def current_from_hello(hello) -> dict[str, int]:
    """What a HELLO tells of the settings (stream and board); the others cannot be read from the device."""
    if hello is None:
        return {}
    mode = hello.stream_mode
    out = {"stream.raw": int(bool(mode & STREAM_RAW)), "stream.orientation": int(bool(mode & STREAM_ORIENTATION)),
           "stream.status": int(bool(mode & STREAM_STATUS)),
           "stream.raw_rate_hz": hello.raw_rate_hz, "stream.orientation_rate_hz": hello.orientation_rate_hz}
    if getattr(hello, "protocol_version", 1) >= 2:
        out["board"] = hello.board_profile
    return out


def show(key: str, value: int) -> str:
    if key == "tap.axes":
        return axes_text(value)
    if key == "board":
        return BOARD_PROFILES.get(value, str(value))
    if key in ("stream.raw", "stream.orientation", "stream.status"):
        return "on" if value else "off"
    if key.endswith("_rate_hz"):
        return f"{value} Hz"
    return SETTINGS[key].physical(value)


@dataclass
class Plan:
    packets: list = field(default_factory=list)
    values: dict = field(default_factory=dict)  # every key of the groups sent → LSB value sent
    notes: list = field(default_factory=list)


def plan_settings(items: list[str], hello=None, settings: dict | None = None) -> Plan:
    """The commands that set ``items`` (``KEY=VALUE``), one per group, in :data:`GROUP_ORDER`. A key of a group
    that is not given keeps the value the sphere reports (``settings``: GET_SETTINGS, protocol 3; else HELLO's
    stream and board), or the firmware's default when it reports none (the notes say so)."""
    given: dict[str, int] = {}
    for item in items:
        key, value = parse_assignment(item)
        if key in given:
            raise SettingError(f"{key} given twice")
        given[key] = value
    known = {**current_from_hello(hello), **(settings or {})}
    plan = Plan()
    for group in GROUP_ORDER:
        keys = [k for k, s in SETTINGS.items() if s.group == group]
        if not any(k in given for k in keys):
            continue
        values = {}
        for k in keys:
            if k in given:
                values[k] = given[k]
            elif k in known:
                values[k] = known[k]
            elif SETTINGS[k].default_lsb is not None:
                values[k] = SETTINGS[k].default_lsb
                plan.notes.append(f"{k} sent as the firmware's default {show(k, values[k])} "
                                  "(the device cannot report it; give it to keep another value)")
            else:
                raise SettingError(f"{k} must be given too: the sphere did not say its current value (no HELLO)")
        plan.values.update(values)
        plan.packets.append(_packet(group, values))
    _check_stream(plan.values, given)
    return plan


def _check_stream(v: dict, given: dict) -> None:
    for part in ("raw", "orientation"):
        on, rate = v.get(f"stream.{part}"), v.get(f"stream.{part}_rate_hz")
        if on is None:
            continue
        if on and not rate:
            raise SettingError(f"stream.{part}=on needs stream.{part}_rate_hz (one of {', '.join(map(str, RATES_HZ))})")
        if not on and f"stream.{part}_rate_hz" in given:  # SET_STREAM: a stream that is off has rate 0
            raise SettingError(f"stream.{part}_rate_hz={rate}: stream.{part} is off, and a stream that is off has no "
                               f"rate; give stream.{part}=on too")


def _packet(group: str, v: dict):
    if group == "tap":
        return SetTap(v["tap.threshold_g"], v["tap.duration_ms"], v["tap.latency_ms"], v["tap.window_ms"], v["tap.axes"])
    if group == "free_fall":
        return SetFreeFall(v["free_fall.threshold_g"], v["free_fall.time_ms"])
    if group == "filter":
        return SetFilter(v["filter.beta"])
    if group == "board":
        return SetBoard(v["board"])
    if group == "stream":
        mode = v["stream.raw"] | v["stream.orientation"] << 1 | v["stream.status"] << 2
        raw = v["stream.raw_rate_hz"] if v["stream.raw"] else 0
        ori = v["stream.orientation_rate_hz"] if v["stream.orientation"] else 0
        return SetStream(mode, raw, ori)
    raise AssertionError(group)
