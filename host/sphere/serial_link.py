"""Opening the sphere's serial port (USB or Bluetooth SPP) with errors that say what to do."""

from __future__ import annotations

import serial

DEFAULT_BAUD = 115200


class PortError(Exception):
    """The port could not be opened or was lost; the message says what to do."""


def open_port(port: str, baud: int = DEFAULT_BAUD, timeout_s: float = 0.1) -> serial.Serial:
    """Open a port for reading frames: 8N1, no flow control, a short read timeout."""
    try:
        return serial.Serial(port, baud, timeout=timeout_s)
    except serial.SerialException as e:
        text = str(e)
        if "No such file" in text or "could not open port" in text and "FileNotFound" in text:
            hint = "is the sphere plugged in (or paired)? list ports with `python3 -m serial.tools.list_ports`"
        elif "Permission denied" in text:
            hint = "add yourself to the group that owns the port (usually `dialout`: sudo usermod -aG dialout $USER, then log in again)"
        elif "busy" in text.lower():
            hint = "another program holds the port (a serial monitor, ModemManager?); close it"
        else:
            hint = "check the port name"
        raise PortError(f"cannot open {port}: {text}; {hint}") from None
    except ValueError as e:
        raise PortError(f"cannot open {port} at {baud} baud: {e}") from None
