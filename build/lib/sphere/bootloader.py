"""The Nano's serial bootloader: finding it, and the avrdude line that writes the firmware through it.

A Nano resets when DTR drops (its auto-reset capacitor), and its bootloader listens for a few hundred
milliseconds before starting the application. Both bootloaders Nanos ship with speak STK500 version 1
(Atmel application note AVR061): Optiboot at 115200 baud (the "new bootloader" in the Arduino IDE) and
the older ATmegaBOOT at 57600. :func:`detect_baud` resets the board at each rate in turn and sends
STK_GET_SYNC until the bootloader answers STK_INSYNC STK_OK.
"""

from __future__ import annotations

import time

# AVR061 §"Command constants"
STK_OK = 0x10
STK_INSYNC = 0x14
CRC_EOP = 0x20
STK_GET_SYNC = 0x30

#: (baud, name): tried in this order
BOOTLOADERS = ((115200, "Optiboot"), (57600, "ATmegaBOOT (old bootloader)"))
MCU = "atmega328p"


def bootloader_name(baud: int) -> str:
    return dict(BOOTLOADERS).get(baud, f"STK500v1 at {baud}")


def _modem_lines(ser, level: bool) -> None:
    """DTR and RTS; a port without modem lines (a pseudo-terminal, Bluetooth SPP) has nothing to pulse:
    there the board's reset button must be pressed by hand."""
    try:
        ser.dtr = level
        ser.rts = level
    except OSError:
        pass


def sync_at(ser, baud: int, window_s: float = 1.0, attempts_gap_s: float = 0.05) -> bool:
    """Reset the board through DTR at ``baud`` and ask for sync until it answers or the window closes."""
    ser.baudrate = baud
    _modem_lines(ser, False)
    time.sleep(0.05)
    ser.reset_input_buffer()
    _modem_lines(ser, True)  # the edge through the auto-reset capacitor pulses the ATmega328P's RESET
    deadline = time.monotonic() + window_s
    seen = b""
    while time.monotonic() < deadline:
        ser.write(bytes((STK_GET_SYNC, CRC_EOP)))
        ser.flush()
        time.sleep(attempts_gap_s)
        seen += ser.read(ser.in_waiting or 1)
        if bytes((STK_INSYNC, STK_OK)) in seen:
            return True
        seen = seen[-1:]
    return False


def detect_baud(ser, bauds=tuple(b for b, _ in BOOTLOADERS), window_s: float = 1.0) -> int | None:
    """The baud rate at which a bootloader answers on the open port ``ser``, or None."""
    for baud in bauds:
        if sync_at(ser, baud, window_s):
            return baud
    return None


def avrdude_command(port: str, baud: int, hex_path, avrdude: str = "avrdude", verify: bool = True) -> list[str]:
    """avrdude writing ``hex_path`` through the bootloader (-D: the bootloader erases page by page)."""
    cmd = [avrdude, "-p", MCU, "-c", "arduino", "-P", str(port), "-b", str(baud), "-D",
           "-U", f"flash:w:{hex_path}:i"]
    if not verify:
        cmd.insert(-2, "-V")
    return cmd
