"""The base of every error the ``sphere`` package raises for a person to read, and the errors more than one
layer raises.

Like pyserial's ``SerialException``, one base lets a caller catch everything the package means to report:
``except SphereError as e: print(f"sphere: {e}")``. Each message is one line that says what was wrong and what
to do. An error that also is a builtin kind keeps that base too (``SettingError(SphereError, ValueError)``), so
callers that catch ``ValueError`` or ``OSError`` go on catching it. This module imports nothing of the
package: every layer may raise these.
"""

from __future__ import annotations


class SphereError(Exception):
    """An error meant for the user: the message says what went wrong and what to do."""


class LinkLost(SphereError):
    """The device went away (unplugged, closed, out of range); the message says how it was noticed and, where
    known, which port and what to do. Raised by the device link (``sphere device``, ``monitor``, ``calibrate``)
    and by the daemon's sources, which then reconnect."""
