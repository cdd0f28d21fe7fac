"""The ``x11`` backend: XTest fake input (any X server with the XTEST extension), through libXtst where it is
installed (:mod:`sphere.daemon.backends.xlib_ctypes`: microseconds a move), else through python-xlib."""

from __future__ import annotations

import os

from sphere.daemon.backends.base import Backend, BackendUnavailable
from sphere.daemon.backends.xlib_ctypes import XConnectionLost, XLibraryMissing, XTest
from sphere.settings import Param

_BUTTON = {"left": 1, "middle": 2, "right": 3}


def _int16(v: int) -> int:
    """A relative motion's offset as the request carries it (INT16; a move never comes near the limits)."""
    return max(-32768, min(32767, int(v)))


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
        self._c = None
        if via in (None, "libXtst"):
            try:
                self._c = XTest(name)
            except XLibraryMissing:
                if via is not None:
                    raise BackendUnavailable("libX11 or libXtst is not installed (apt-get install libx11-6 libxtst6)") \
                        from None
            except (ConnectionRefusedError, LookupError) as e:
                raise BackendUnavailable(str(e)) from None
        self.via = "libXtst" if self._c is not None else "python-xlib"
        if self._c is not None:
            self._size = self._c.size
            return
        try:
            from Xlib import X, display as xdisplay  # optional: python-xlib (the daemon extra)
            from Xlib.ext import xtest  # optional: python-xlib
        except ImportError:
            raise BackendUnavailable("python-xlib is not installed: pip install python-xlib") from None
        try:
            self.display = xdisplay.Display(name)
        except Exception as e:  # Xlib raises several kinds for a missing or refused display
            raise BackendUnavailable(f"cannot connect to X display {name}: {e}") from None
        if not self.display.has_extension("XTEST"):
            self.display.close()
            raise BackendUnavailable(f"X display {name} has no XTEST extension")
        self._X = X
        self._xtest = xtest
        screen = self.display.screen()
        self._size = (screen.width_in_pixels, screen.height_in_pixels)

    def move(self, dx: int, dy: int) -> None:
        # XTest relative motion (detail True): one request, no round trip. The server adds the offset to where the
        # pointer is when it processes it (so a real mouse's moves in between are kept) and clips it to the
        # screen; since X.Org 1.7 the XTest device's relative motion gets no pointer acceleration (Xext/xtest.c
        # passes no POINTER_ACCELERATE to GetPointerEvents), so the mapper's own curve is what the hand gets.
        # Before, the position was read back first (XQueryPointer): a round trip on the pointer's path.
        if self._c is not None:
            self._c.move(_int16(dx), _int16(dy))
            return
        self._xtest.fake_input(self.display, self._X.MotionNotify, detail=True, x=_int16(dx), y=_int16(dy))
        self.display.flush()

    def move_to(self, x: int, y: int) -> None:
        if self._c is not None:
            self._c.move_to(int(x), int(y))
            return
        self._xtest.fake_input(self.display, self._X.MotionNotify, x=int(x), y=int(y))
        self.display.flush()

    def press(self, button: str) -> None:
        if self._c is not None:
            self._c.button(_BUTTON[button], True)
            return
        self._xtest.fake_input(self.display, self._X.ButtonPress, _BUTTON[button])
        self.display.flush()

    def release(self, button: str) -> None:
        if self._c is not None:
            self._c.button(_BUTTON[button], False)
            return
        self._xtest.fake_input(self.display, self._X.ButtonRelease, _BUTTON[button])
        self.display.flush()

    def screen_size(self):
        return self._size

    def sync(self) -> None:
        """Wait until the server has done every request sent (one round trip)."""
        if self._c is not None:
            self._c.sync()
        else:
            self.display.sync()

    def close(self) -> None:
        # the moves are requests without replies: wait until the server has done them all, so the pointer is
        # where the last one put it once the daemon has stopped (a replay, a script reading it back)
        if self._c is not None:
            try:
                self._c.sync()
            except XConnectionLost:
                pass
            self._c.close()
            return
        try:
            self.display.sync()
            self.display.close()
        except Exception:
            pass
