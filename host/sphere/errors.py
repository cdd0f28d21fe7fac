"""The base of every error the ``sphere`` package raises for a person to read, the errors more than one layer
raises, and how a command says that its output could not be written.

Like pyserial's ``SerialException``, one base lets a caller catch everything the package means to report:
``except SphereError as e: print(f"sphere: {e}")``. Each message is one line that says what was wrong and what
to do. An error that also is a builtin kind keeps that base too (``SettingError(SphereError, ValueError)``), so
callers that catch ``ValueError`` or ``OSError`` go on catching it. This module imports nothing of the
package: every layer may use it.
"""

from __future__ import annotations

import errno
import os
import sys


class SphereError(Exception):
    """An error meant for the user: the message says what went wrong and what to do."""


class LinkLost(SphereError):
    """The device went away (unplugged, closed, out of range); the message says how it was noticed and, where
    known, which port and what to do. Raised by the device link (``sphere device``, ``monitor``, ``calibrate``)
    and by the daemon's sources, which then reconnect."""


#: errors of a write that failed because of where the output goes (a full disk, /dev/full, a dead terminal)
OUTPUT_ERRNOS = (errno.ENOSPC, errno.EIO, errno.EFBIG, errno.EDQUOT, errno.EROFS)


def output_failed(prog: str, e: BaseException) -> int | None:
    """For an OSError of :data:`OUTPUT_ERRNOS`: one line on stderr and the exit status 1 (stdout is pointed at
    /dev/null, so that Python's final flush does not fail again); None for any other error."""
    if not isinstance(e, OSError) or e.errno not in OUTPUT_ERRNOS:
        return None
    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass
    print(f"{prog}: cannot write the output: {e.strerror}; make room (or write it somewhere else)", file=sys.stderr)
    return 1
