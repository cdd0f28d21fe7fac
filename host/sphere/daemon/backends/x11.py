"""The ``x11`` backend: XTest fake input (any X server with the XTEST extension), through libXtst where it is
installed (:mod:`sphere.daemon.backends.xlib_ctypes`: microseconds a move), else through python-xlib."""

from __future__ import annotations

import os

from sphere.daemon.backends.base import Backend, BackendUnavailable
from sphere.daemon.backends.xlib_ctypes import XLibraryMissing, XTest, lost_display
from sphere.settings import Param

_BUTTON = {"left": 1, "middle": 2, "right": 3}


def _int16(v: int) -> int:
    """A relative motion's offset as the request carries it (INT16; a move never comes near the limits)."""
    return max(-32768, min(32767, int(v)))


class _PythonXlibXTest:
    """XTest through python-xlib, with :class:`~sphere.daemon.backends.xlib_ctypes.XTest`'s calls: where libX11 or
    libXtst is missing. Each request is built in Python (tens of µs more a move)."""

    def __init__(self, name: str):
        try:
            from Xlib import X, display as xdisplay  # optional: python-xlib (the daemon extra)
            from Xlib.error import ConnectionClosedError  # optional: python-xlib
            from Xlib.ext import xtest  # optional: python-xlib
        except ImportError:
            raise BackendUnavailable("neither libX11 + libXtst (apt-get install libx11-6 libxtst6) nor python-xlib "
                                     "(pip install python-xlib) is installed") from None
        try:
            self.display = xdisplay.Display(name)
        except Exception as e:  # Xlib raises several kinds for a missing or refused display
            raise BackendUnavailable(f"cannot connect to X display {name}: {e}") from None
        if not self.display.has_extension("XTEST"):
            self.display.close()
            raise BackendUnavailable(f"X display {name} has no XTEST extension")
        self.name = name
        self._X = X
        self._fake = xtest.fake_input
        self._closed = ConnectionClosedError
        screen = self.display.screen()
        self.size = (screen.width_in_pixels, screen.height_in_pixels)

    def _send(self, *request, **fields) -> None:
        try:
            self._fake(self.display, *request, **fields)
            self.display.flush()
        except (self._closed, BrokenPipeError, ConnectionResetError):
            raise lost_display(self.name) from None

    def move(self, dx: int, dy: int) -> None:
        self._send(self._X.MotionNotify, detail=True, x=dx, y=dy)

    def move_to(self, x: int, y: int) -> None:
        self._send(self._X.MotionNotify, x=x, y=y)

    def button(self, number: int, down: bool) -> None:
        self._send(self._X.ButtonPress if down else self._X.ButtonRelease, number)

    def sync(self) -> None:
        try:
            self.display.sync()
        except (self._closed, BrokenPipeError, ConnectionResetError):
            raise lost_display(self.name) from None

    def close(self) -> None:
        self.display.close()


#: ``via`` → the XTest connection class
_VIA = {"libXtst": XTest, "python-xlib": _PythonXlibXTest}


class X11Backend(Backend):
    NAME = "x11"
    PARAMS = {"display": Param("", doc="X display of the x11 backend (empty = `$DISPLAY`)")}

    def __init__(self, display: str | None = None, via: str | None = None):
        """``via``: ``libXtst`` (the C libraries through ctypes: :mod:`sphere.daemon.backends.xlib_ctypes`) or
        ``python-xlib``; None = libXtst where libX11 and libXtst are installed, else python-xlib."""
        name = display or os.environ.get("DISPLAY")
        if not name:
            raise BackendUnavailable("no X display: DISPLAY is not set (on Wayland use the uinput backend)")
        self.display_name = name
        self.via = via or "libXtst"
        try:
            self._xtest = _VIA[self.via](name)
        except XLibraryMissing as e:
            if via is not None:
                raise BackendUnavailable(str(e)) from None
            self.via = "python-xlib"
            self._xtest = _PythonXlibXTest(name)
        except (ConnectionRefusedError, LookupError) as e:
            raise BackendUnavailable(str(e)) from None
        self._size = self._xtest.size

    def move(self, dx: int, dy: int) -> None:
        # XTest relative motion: one request, no round trip. The server adds the offset to where the pointer is
        # when it processes it (so a real mouse's moves in between are kept) and clips it to the screen; since
        # X.Org 1.7 the XTest device's relative motion gets no pointer acceleration (Xext/xtest.c passes no
        # POINTER_ACCELERATE to GetPointerEvents), so the mapper's own curve is what the hand gets. Before, the
        # position was read back first (XQueryPointer): a round trip on the pointer's path.
        self._xtest.move(_int16(dx), _int16(dy))

    def move_to(self, x: int, y: int) -> None:
        self._xtest.move_to(int(x), int(y))

    def press(self, button: str) -> None:
        self._xtest.button(_BUTTON[button], True)

    def release(self, button: str) -> None:
        self._xtest.button(_BUTTON[button], False)

    def screen_size(self):
        return self._size

    def sync(self) -> None:
        """Wait until the server has done every request sent (one round trip)."""
        self._xtest.sync()

    def close(self) -> None:
        # the moves are requests without replies: wait until the server has done them all, so the pointer is
        # where the last one put it once the daemon has stopped (a replay, a script reading it back)
        try:
            self._xtest.sync()
        except Exception:  # the server is gone (XConnectionLost, python-xlib's ConnectionClosedError): nothing to wait for
            pass
        try:
            self._xtest.close()
        except Exception:  # python-xlib on a closed connection
            pass
