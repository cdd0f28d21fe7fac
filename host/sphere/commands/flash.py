"""`sphere flash [--port P]`: write the firmware to a Nano through its bootloader, then wait for the
HELLO of the firmware just written and print its version."""

from __future__ import annotations

import shutil
import subprocess
import sys
import time
from pathlib import Path

from sphere import paths
from sphere.daemon.sources.serial import DEFAULT_USB_IDS, candidate_ports
from sphere.errors import SphereError
from sphere.link import bootloader
from sphere.link.port import DEFAULT_BAUD, PortError, open_port
from sphere.protocol import FrameDecoder, GetHello, encode_frame
from sphere.sim.board import BoardUnavailable, firmware_elf

HELP = "write the firmware to the Nano (finds the image and the bootloader's baud rate, runs avrdude)"
DESCRIPTION = (
    "Write the sphere's firmware to an Arduino Nano over USB. The image is $SPHERE_FIRMWARE, the checkout's "
    "firmware/build/sphere.hex (built with `make -C firmware` when missing) or the one installed with the "
    "package. The bootloader's baud rate is found by asking it for sync (Optiboot 115200, the old "
    "bootloader 57600); avrdude writes and verifies the image; then the command waits for the firmware's "
    "HELLO and prints its version."
)
HELLO_TIMEOUT_S = 6.0


class FlashError(SphereError):
    """Flashing cannot go on; the message says what to do. ``code`` 2: a bad flag, image or port (nothing was
    written); 1: the board did not answer or avrdude failed."""

    def __init__(self, message: str, code: int = 2):
        super().__init__(message)
        self.code = code


def add_arguments(p) -> None:
    p.add_argument("--port", help="the Nano's serial port (default: /dev/sphere, or the one USB-serial Nano plugged in)")
    p.add_argument("--image", help="a .hex image to write (default: the firmware image, see above)")
    p.add_argument("--baud", type=int, choices=(115200, 57600),
                   help="the bootloader's baud rate (default: detected)")
    p.add_argument("--avrdude", default="avrdude", help="the avrdude program (default: avrdude on PATH)")
    p.add_argument("--no-verify", action="store_true", help="skip avrdude's read-back verification")
    p.add_argument("--no-hello", action="store_true", help="do not wait for the firmware's HELLO afterwards")


def find_image(given: str | None) -> Path:
    if given:
        image = Path(given)
        if image.is_dir():
            raise FlashError(f"{image} is a folder: give the .hex image file")
        if not image.is_file():
            raise FlashError(f"{image}: no such image file")
        if image.suffix.lower() != ".hex":
            raise FlashError(f"{image}: avrdude is given an Intel HEX file here (.hex); `make -C firmware` makes one")
        try:
            with open(image, "rb") as f:
                head = f.read(1)
        except OSError as e:
            raise FlashError(f"{image}: cannot read: {e.strerror}") from None
        if head != b":":
            raise FlashError(f"{image}: not an Intel HEX file (its records start with ':'); `make -C firmware` makes one")
        return image
    image = paths.firmware_image(".hex")
    build_dir = paths.firmware_build_dir()
    if build_dir is not None and image == build_dir / "sphere.hex":
        try:
            # the checkout's own image: made when missing or older than firmware/src (the same `make -C firmware`
            # writes the .hex beside the .elf), so a Nano is never flashed with an image of older sources
            firmware_elf(build=True)
        except BoardUnavailable as e:
            raise FlashError(str(e)) from None
    if not image.exists():
        raise FlashError(f"no firmware image at {image}: {paths.firmware_missing_hint()}")
    return image


def find_port(given: str | None) -> str:
    if given:
        return given
    found = [path for path, _ in candidate_ports(["/dev/sphere"], DEFAULT_USB_IDS)]
    if len(found) == 1:
        return found[0]
    if not found:
        raise FlashError("no Nano found (no /dev/sphere, no CH340/FT232R/CP2102 USB-serial port): plug it in, "
                         "or name its port with --port")
    raise FlashError(f"several possible Nanos: {', '.join(found)}; name one with --port")


def wait_for_hello(port: str, timeout_s: float = HELLO_TIMEOUT_S):
    """Open the port at the firmware's rate and wait for a HELLO (asking with GET_HELLO after 1.5 s)."""
    try:
        ser = open_port(port, DEFAULT_BAUD, timeout_s=0.1)
    except PortError as e:
        raise FlashError(str(e)) from None
    decoder = FrameDecoder("device")
    start = time.monotonic()
    asked = 0.0
    try:
        while time.monotonic() - start < timeout_s:
            data = ser.read(256)
            for packet in decoder.feed(data):
                if packet.NAME == "HELLO":
                    return packet
            elapsed = time.monotonic() - start
            if elapsed > 1.5 and elapsed - asked > 1.0:  # the bootloader's wait is over by now
                ser.write(encode_frame(GetHello(), 0))
                asked = elapsed
    finally:
        ser.close()
    return None


def flash(args, out=None) -> int:
    """:func:`_flash`; Ctrl-C says what it left on the Nano (exit 130)."""
    state = {"now": "nothing was written"}
    try:
        return _flash(args, out or sys.stdout, state)
    except KeyboardInterrupt:
        raise FlashError(f"interrupted; {state['now']}", 130) from None


def _flash(args, out, state) -> int:

    image = find_image(args.image)
    avrdude = shutil.which(args.avrdude)
    if avrdude is None:
        raise FlashError(f"{args.avrdude}: not found; install avrdude (Debian: `sudo apt-get install avrdude`)")
    port = find_port(args.port)
    # the bootloader is asked for sync also at a --baud given: a port where none answers is one line, not avrdude's
    # ten attempts
    bauds = (args.baud,) if args.baud else tuple(b for b, _ in bootloader.BOOTLOADERS)
    try:
        ser = open_port(port, bauds[0], timeout_s=0.05)
    except PortError as e:
        raise FlashError(str(e)) from None
    try:
        baud = bootloader.detect_baud(ser, bauds)
    finally:
        ser.close()
    if baud is None:
        raise FlashError(f"no bootloader answered on {port} at {' or '.join(map(str, bauds))} baud: is it a Nano? "
                         "Press its reset button just as you run this again"
                         + (" (or without --baud: both rates are tried)" if args.baud else ", or give --baud"), 1)
    print(f"{port}: {bootloader.bootloader_name(baud)} at {baud} baud; writing {image}", file=out, flush=True)
    cmd = bootloader.avrdude_command(port, baud, image, avrdude=avrdude, verify=not args.no_verify)
    state["now"] = ("avrdude was writing: the Nano may hold part of the image; its bootloader is untouched, so "
                    "`sphere flash` again writes the whole image")
    r = subprocess.run(cmd, capture_output=True, text=True)  # on Ctrl-C it ends avrdude (SIGINT, then SIGKILL)
    if r.returncode != 0:
        tail = "\n".join((r.stderr or r.stdout).strip().splitlines()[-8:])
        raise FlashError(f"avrdude failed (exit status {r.returncode}):\n{tail}\ncommand: {' '.join(cmd)}", 1)
    print("written" + ("" if args.no_verify else " and verified"), file=out, flush=True)
    state["now"] = "the image was written" + ("" if args.no_verify else " and verified")
    if args.no_hello:
        return 0
    hello = wait_for_hello(port)
    if hello is None:
        raise FlashError(f"the image is written but no HELLO came from {port} within {HELLO_TIMEOUT_S:g} s: "
                         "check the sensors' wiring (hardware/README.md) and watch the port with `sphere monitor`", 1)
    j = hello.to_json()
    print(f"firmware {j['firmware_version']} (protocol {hello.protocol_version}); sensors found: "
          f"{', '.join(j['sensors_found']) or 'none'}", file=out)
    return 0


def run(args) -> int:
    try:
        return flash(args)
    except FlashError as e:
        print(f"sphere flash: {e}", file=sys.stderr)
        return e.code
