"""`sphere device`: read and change the sphere's settings on its port (tap, free fall, stream, filter gain,
board profile), make it blink, reboot it."""

from __future__ import annotations

import argparse
import sys

from sphere import argtypes
from sphere.daemon.sources.base import version_problem
from sphere.errors import LinkLost, SphereError
from sphere.link.device import DeviceLink
from sphere.link.device_settings import (
    SETTINGS,
    SettingError,
    current_from_hello,
    current_from_settings,
    parse_assignment,
    plan_settings,
    settings_state_text,
    show,
)
from sphere.link.port import PortError, open_port
from sphere.protocol import Identify, Reboot
from sphere.protocol.packets import (
    CAL_ACCEL_CALIBRATED,
    CAL_EEPROM_INVALID,
    CAL_FROM_EEPROM,
    CAL_GYRO_BIAS_ESTIMATED,
    CAL_GYRO_BIAS_VALID,
    CAL_MAG_CALIBRATED,
    REBOOT_MAGIC,
    ClearSettings,
    GetSettings,
    Result,
    SaveSettings,
)

HELP = "read, change and save the sphere's settings (tap, free fall, stream, filter, board), identify, reboot"
DESCRIPTION = """\
  sphere device --port P get                       what the sphere reports (firmware, sensors, stream, board)
  sphere device --port P set KEY=VALUE ...         change settings, e.g. tap.threshold_g=2.5 tap.axes=z
  sphere device --port P save                      keep the settings in use over power-off (EEPROM)
  sphere device --port P clear                     forget the saved settings: defaults at the next power-up
  sphere device --port P identify [SECONDS]        blink the sphere's LED (default 5 s)
  sphere device --port P reboot                    restart the firmware
  sphere device keys                               every KEY, its unit and range

Settings take effect at once; `save` keeps them (the board profile is always kept). sphere-mouse applies
the [device] section of its config at every connect, over what the sphere saved. A command sets a whole
group (SET_TAP carries all five tap settings): a key of the group you do not give keeps the value the sphere
reports (firmware with protocol 3 reports every setting; older firmware only the stream and the board, and
the others are then sent as the firmware's default — the output says which)."""


def add_arguments(p) -> None:
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.add_argument("--port", help="the sphere's serial port (e.g. /dev/ttyUSB0, /dev/rfcomm0, /dev/sphere)")
    p.add_argument("--baud", type=argtypes.baud, default=115200)
    p.add_argument("--timeout", type=argtypes.seconds, default=1.0, metavar="SECONDS", help="wait this long for each REPLY")
    p.add_argument("action", choices=("get", "set", "save", "clear", "identify", "reboot", "keys"))
    p.add_argument("items", nargs="*", metavar="KEY=VALUE", help="for set: the settings; for identify: seconds")


def _keys() -> str:
    lines = []
    for key, s in SETTINGS.items():
        default = f" (firmware default {show(key, s.default_lsb)})" if s.default_lsb is not None and key != "board" else ""
        lines.append(f"  {key:28s} {s.describe()}{default}")
    return "\n".join(lines)


class _Failed(SphereError):
    """What went wrong; ``code`` 2 for a bad command line or port (nothing was sent), 1 for a sphere that did
    not answer or refused."""

    def __init__(self, message: str, code: int = 2):
        super().__init__(message)
        self.code = code


def _open(args):
    if not args.port:
        raise _Failed("name the sphere's port with --port (e.g. --port /dev/ttyUSB0)")
    try:
        ser = open_port(args.port, args.baud)
    except PortError as e:
        raise _Failed(str(e)) from None
    link = DeviceLink(ser, name=args.port)
    hello = link.hello(timeout_s=3.0)
    if hello is None:
        ser.close()
        rate = ("at 115200 baud?" if args.baud == 115200 else
                f"at {args.baud} baud? (the firmware talks at 115200 until asked otherwise: leave --baud out)")
        raise _Failed(f"no HELLO from {args.port} within 3 s: is it the sphere (its firmware flashed: `sphere flash`), "
                      + rate, 1)

    problem = version_problem(hello)
    if problem:
        ser.close()
        raise _Failed(problem)
    return ser, link, hello


def _read_settings(link, hello, timeout_s: float) -> tuple[dict, int] | None:
    """Every setting the sphere reports with GET_SETTINGS (key → LSB) and settings_state; None for firmware
    older than protocol 3, which has no such command."""
    if hello.protocol_version < 3:
        return None
    reply = link.command(GetSettings(), timeout_s)
    problem = _reply_problem(GetSettings, reply)
    if problem:
        raise _Failed(problem, 1)
    try:
        packets, state = reply.settings()
    except ValueError as e:
        raise _Failed(f"GET_SETTINGS: {e}", 1) from None
    return current_from_settings(packets), state


def _calibration(state: int, names: list[str], port: str) -> str:
    """HELLO's ``calibration_state`` (spec §4.1) in words, its bit names after them."""
    done = [w for w, bit in (("accelerometer", CAL_ACCEL_CALIBRATED), ("magnetometer", CAL_MAG_CALIBRATED)) if state & bit]
    parts = [" and ".join(done) + " calibrated" if done else "accelerometer and magnetometer not calibrated"]
    if state & CAL_FROM_EEPROM:
        parts[0] += ", loaded from the sphere's EEPROM"
    elif state & CAL_EEPROM_INVALID:  # blank or damaged: the firmware cannot tell which
        parts[0] += (", not saved on the sphere" if done else
                     f" (none saved on the sphere: `sphere calibrate --port {port}` makes and saves one)")
    parts.append("gyro bias measured on the sphere" if state & CAL_GYRO_BIAS_ESTIMATED else
                 "gyro bias set" if state & CAL_GYRO_BIAS_VALID else
                 "gyro bias not measured yet (the sphere measures it once it lies still)")
    return "; ".join(parts) + f" [{', '.join(names) or 'none'}]"


def _describe(hello, settings, port: str) -> list[str]:
    j = hello.to_json()
    out = [f"firmware {j['firmware_version']} (protocol {hello.protocol_version}); sensors found: "
           f"{', '.join(j['sensors_found']) or 'none'}; IMU {hello.imu_rate_hz} Hz, magnetometer {hello.mag_rate_hz} Hz",
           "calibration: " + _calibration(hello.calibration_state, j["calibration_state"], port)]
    values = {**current_from_hello(hello), **(settings[0] if settings else {})}
    for key in SETTINGS:
        if key in values:
            out.append(f"{key} = {show(key, values[key])}")
    if settings:
        out.append(settings_state_text(settings[1]))
    else:
        out.append("tap.*, free_fall.*, filter.beta: this firmware cannot report them (protocol 3 can: `sphere flash`); "
                   "`sphere device keys` gives the firmware's defaults")
    return out


def _reply_problem(packet, reply) -> str | None:
    if reply is None:
        return f"{packet.NAME}: no REPLY (is the sphere still there?)"
    if not reply.ok:
        try:
            name = Result(reply.result).name.lower()
        except ValueError:
            name = str(reply.result)
        return f"{packet.NAME}: the sphere refused it ({name})"
    return None


def _ask(link, packet, timeout_s: float, after: str = "", unknown: str = "") -> None:
    """Send a command and wait for its REPLY; _Failed with what went wrong unless it is OK, and then ``after`` for a
    refusal (a command not OK changes nothing, spec §5) or ``unknown`` for silence (the sphere may have carried it
    out and its REPLY been lost)."""
    reply = link.command(packet, timeout_s)
    problem = _reply_problem(packet, reply)
    if problem:
        raise _Failed(problem + (after if reply is not None else unknown), 1)


def run(args) -> int:
    try:
        return _run(args)
    except _Failed as e:
        print(f"sphere device: {e}", file=sys.stderr)
        return e.code
    except LinkLost as e:  # unplugged (or the board gone) while a command waited for its REPLY
        print(f"sphere device: {e}", file=sys.stderr)
        return 1


def _run(args) -> int:
    if args.action == "keys":
        print(_keys())
        return 0
    if args.action == "set" and not args.items:
        raise _Failed("set what? give KEY=VALUE ... (`sphere device keys` lists them)")
    if args.action in ("get", "save", "clear", "reboot") and args.items:
        raise _Failed(f"{args.action} takes no KEY=VALUE")
    seconds = 5
    if args.action == "identify":
        if len(args.items) > 1 or (args.items and not args.items[0].isdigit()):
            raise _Failed("identify takes one number of seconds (1 … 60)")
        seconds = int(args.items[0]) if args.items else 5
        if not 1 <= seconds <= 60:
            raise _Failed(f"identify {seconds}: seconds must be 1 … 60")
    if args.action == "set":
        try:  # checked before the port is opened: a typo touches nothing
            for item in args.items:
                parse_assignment(item)
        except SettingError as e:
            raise _Failed(str(e)) from None
    ser, link, hello = _open(args)
    try:
        if args.action == "get":
            print("\n".join(_describe(hello, _read_settings(link, hello, args.timeout), args.port)))
            return 0
        if args.action in ("save", "clear"):
            if hello.protocol_version < 3:
                raise _Failed(f"this firmware (protocol {hello.protocol_version}) cannot {args.action} its settings: "
                              "flash the current one (`sphere flash`)", 1)
            packet = SaveSettings() if args.action == "save" else ClearSettings()
            _ask(link, packet, max(args.timeout, 2.0))  # 17 EEPROM bytes take ~60 ms to write
            board = show("board", hello.board_profile)  # SET_BOARD stores it apart: neither command touches it
            print("saved: the sphere starts with these settings at every power-up" if args.action == "save" else
                  f"cleared: the sphere starts with its default settings at the next power-up; its board profile "
                  f"({board}) is stored apart and stays (`set board=...` changes it)")
            return 0
        if args.action == "identify":
            _ask(link, Identify(seconds), args.timeout)
            print(f"the sphere's LED blinks for {seconds} s")
            return 0
        if args.action == "reboot":
            _ask(link, Reboot(REBOOT_MAGIC), args.timeout)
            again = link.hello(timeout_s=5.0)
            print("rebooted" + (f"; firmware {again.to_json()['firmware_version']} is back" if again else
                                "; no HELLO yet (a USB Nano's bootloader waits ~1 s first)"))
            return 0
        reported = _read_settings(link, hello, args.timeout)
        try:
            plan = plan_settings(args.items, hello, reported[0] if reported else None)
        except SettingError as e:
            raise _Failed(str(e)) from None
        for i, packet in enumerate(plan.packets):
            before = "; the settings before it were applied" if i else ""
            _ask(link, packet, args.timeout, before or "; nothing was changed",
                 f"; whether the sphere took it is unknown (`sphere device --port {args.port} get` reads what it holds)"
                 + before)
        for note in plan.notes:
            print(f"note: {note}", file=sys.stderr)
        given = {item.split("=", 1)[0].strip() for item in args.items}
        kept = []  # what happens at power-off: SET_BOARD stores the profile itself, the others wait for `save`
        if "board" in given:
            kept.append("the board profile is stored on the sphere at once")
        if reported and given - {"board"}:
            kept.append("`sphere device save` keeps " + ("the others" if "board" in given else "them") + " over power-off")
        print("set: " + ", ".join(f"{k} = {show(k, v)}" for k, v in plan.values.items() if k in given)
              + "".join(f"; {k}" for k in kept))
        return 0
    finally:
        ser.close()
