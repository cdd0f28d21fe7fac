"""`sphere device`: read and change the sphere's settings on its port (tap, free fall, stream, filter gain,
board profile), make it blink, reboot it."""

from __future__ import annotations

import argparse
import sys

from sphere import argtypes

HELP = "read or change the sphere's settings (tap, free fall, stream, filter, board), identify, reboot"
DESCRIPTION = """\
  sphere device --port P get                       what the sphere reports (firmware, sensors, stream, board)
  sphere device --port P set KEY=VALUE ...         change settings, e.g. tap.threshold_g=2.5 tap.axes=z
  sphere device --port P identify [SECONDS]        blink the sphere's LED (default 5 s)
  sphere device --port P reboot                    restart the firmware
  sphere device keys                               every KEY, its unit and range

Settings take effect at once and last until the sphere restarts (the board profile is kept in EEPROM).
A command sets a whole group (SET_TAP carries all five tap settings): a key of the group you do not give
keeps the value the sphere reports, or, when it cannot report it, is sent as the firmware's default — the
output says which."""


def add_arguments(p) -> None:
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.add_argument("--port", help="the sphere's serial port (e.g. /dev/ttyUSB0, /dev/rfcomm0, /dev/sphere)")
    p.add_argument("--baud", type=argtypes.baud, default=115200)
    p.add_argument("--timeout", type=argtypes.seconds, default=1.0, metavar="SECONDS", help="wait this long for each REPLY")
    p.add_argument("action", choices=("get", "set", "identify", "reboot", "keys"))
    p.add_argument("items", nargs="*", metavar="KEY=VALUE", help="for set: the settings; for identify: seconds")


def _keys() -> str:
    from sphere.device_settings import SETTINGS, show

    lines = []
    for key, s in SETTINGS.items():
        default = f" (firmware default {show(key, s.default_lsb)})" if s.default_lsb is not None and key != "board" else ""
        lines.append(f"  {key:28s} {s.describe()}{default}")
    return "\n".join(lines)


class _Failed(Exception):
    """What went wrong; ``code`` 2 for a bad command line or port (nothing was sent), 1 for a sphere that did
    not answer or refused."""

    def __init__(self, message: str, code: int = 2):
        super().__init__(message)
        self.code = code


def _open(args):
    from sphere.device_link import DeviceLink
    from sphere.serial_link import PortError, open_port

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
        raise _Failed(f"no HELLO from {args.port} within 3 s: is it the sphere (its firmware flashed: `sphere flash`), "
                      "at 115200 baud?", 1)
    from sphere.daemon.sources import version_problem

    problem = version_problem(hello)
    if problem:
        ser.close()
        raise _Failed(problem)
    return ser, link, hello


def _describe_hello(hello) -> list[str]:
    from sphere.device_settings import current_from_hello, show

    j = hello.to_json()
    out = [f"firmware {j['firmware_version']} (protocol {hello.protocol_version}); sensors found: "
           f"{', '.join(j['sensors_found']) or 'none'}; IMU {hello.imu_rate_hz} Hz, magnetometer {hello.mag_rate_hz} Hz; "
           f"calibration: {', '.join(j['calibration_state']) or 'none'}"]
    for key, value in current_from_hello(hello).items():
        out.append(f"{key} = {show(key, value)}")
    out.append("tap.*, free_fall.*, filter.beta: set with `sphere device set` (the sphere cannot report them; "
               "`sphere device keys` gives the firmware's defaults)")
    return out


def _reply_problem(packet, reply) -> str | None:
    if reply is None:
        return f"{packet.NAME}: no REPLY (is the sphere still there?)"
    if not reply.ok:
        from sphere.protocol.packets import Result

        try:
            name = Result(reply.result).name.lower()
        except ValueError:
            name = str(reply.result)
        return f"{packet.NAME}: the sphere refused it ({name})"
    return None


def _ask(link, packet, timeout_s: float, after: str = "") -> None:
    """Send a command and wait for its REPLY; _Failed with what went wrong (and ``after``) unless it is OK."""
    problem = _reply_problem(packet, link.command(packet, timeout_s))
    if problem:
        raise _Failed(problem + after, 1)


def run(args) -> int:
    try:
        return _run(args)
    except _Failed as e:
        print(f"sphere device: {e}", file=sys.stderr)
        return e.code


def _run(args) -> int:
    from sphere.device_settings import SettingError, plan_settings, show

    if args.action == "keys":
        print(_keys())
        return 0
    if args.action == "set" and not args.items:
        raise _Failed("set what? give KEY=VALUE ... (`sphere device keys` lists them)")
    if args.action in ("get", "reboot") and args.items:
        raise _Failed(f"{args.action} takes no KEY=VALUE")
    seconds = 5
    if args.action == "identify":
        if len(args.items) > 1 or (args.items and not args.items[0].isdigit()):
            raise _Failed("identify takes one number of seconds (1 … 60)")
        seconds = int(args.items[0]) if args.items else 5
        if not 1 <= seconds <= 60:
            raise _Failed(f"identify {seconds}: seconds must be 1 … 60")
    if args.action == "set":
        from sphere.device_settings import parse_assignment

        try:  # checked before the port is opened: a typo touches nothing
            for item in args.items:
                parse_assignment(item)
        except SettingError as e:
            raise _Failed(str(e)) from None
    ser, link, hello = _open(args)
    try:
        if args.action == "get":
            print("\n".join(_describe_hello(hello)))
            return 0
        if args.action == "identify":
            from sphere.protocol import Identify

            _ask(link, Identify(seconds), args.timeout)
            print(f"the sphere's LED blinks for {seconds} s")
            return 0
        if args.action == "reboot":
            from sphere.protocol import Reboot
            from sphere.protocol.packets import REBOOT_MAGIC

            _ask(link, Reboot(REBOOT_MAGIC), args.timeout)
            again = link.hello(timeout_s=5.0)
            print("rebooted" + (f"; firmware {again.to_json()['firmware_version']} is back" if again else
                                "; no HELLO yet (a USB Nano's bootloader waits ~1 s first)"))
            return 0
        try:
            plan = plan_settings(args.items, hello)
        except SettingError as e:
            raise _Failed(str(e)) from None
        for i, packet in enumerate(plan.packets):
            _ask(link, packet, args.timeout, "; the settings before it were applied" if i else "; nothing was changed")
        for note in plan.notes:
            print(f"note: {note}", file=sys.stderr)
        given = {item.split("=", 1)[0].strip() for item in args.items}
        print("set: " + ", ".join(f"{k} = {show(k, v)}" for k, v in plan.values.items() if k in given))
        return 0
    finally:
        ser.close()
