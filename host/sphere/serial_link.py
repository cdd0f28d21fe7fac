"""Opening the sphere's serial port (USB or Bluetooth SPP) with errors that say what to do."""

from __future__ import annotations

import serial

DEFAULT_BAUD = 115200


class PortError(Exception):
    """The port could not be opened or was lost; the message says what to do."""


def _hint(text: str) -> str:
    if "No such file" in text or "FileNotFound" in text:
        return "is the sphere plugged in (or paired)? list ports with `python3 -m serial.tools.list_ports`"
    if "Permission denied" in text:
        return ("add yourself to the group that owns the port (usually `dialout`: sudo usermod -aG dialout $USER, "
                "then log in again)")
    if "busy" in text.lower():
        return "another program holds the port (a serial monitor, ModemManager?); close it"
    return "check the port name"


def open_port(port: str, baud: int = DEFAULT_BAUD, timeout_s: float = 0.1, *, reset_on_open: bool = True,
              write_timeout_s: float | None = None) -> serial.Serial:
    """Open a port for reading frames: 8N1, no flow control, a short read timeout.

    ``reset_on_open=False`` holds DTR low while opening, so a USB Nano is not reset (the kernel may still
    pulse it on some adapters); Bluetooth SPP ports have no DTR to pulse.
    """
    ser = serial.Serial()
    ser.port = port
    try:
        ser.baudrate = baud
    except ValueError as e:
        raise PortError(f"cannot open {port} at {baud} baud: {e}") from None
    ser.timeout = timeout_s
    ser.write_timeout = write_timeout_s
    if not reset_on_open:
        ser.dtr = False  # applied at open
    try:
        ser.open()
    except (serial.SerialException, OSError) as e:
        raise PortError(f"cannot open {port}: {e}; {_hint(str(e))}") from None
    return ser
