"""The ``x11`` backend: XTest fake input through python-xlib (any X server with the XTEST extension)."""

from __future__ import annotations

import os

from sphere.daemon.backends.base import Backend, BackendUnavailable
from sphere.settings import Param

_BUTTON = {"left": 1, "middle": 2, "right": 3}


def _int16(v: int) -> int:
    """A relative motion's offset as the request carries it (INT16; a move never comes near the limits)."""
    return max(-32768, min(32767, int(v)))


class X11Backend(Backend):
    NAME = "x11"
    PARAMS = {"display": Param("", doc="X display of the x11 backend (empty = `$DISPLAY`)")}

    def __init__(self, display: str | None = None):
        name = display or os.environ.get("DISPLAY")
        if not name:
            raise BackendUnavailable("no X display: DISPLAY is not set (on Wayland use the uinput backend)")
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
        self.display_name = name
        screen = self.display.screen()
        self._size = (screen.width_in_pixels, screen.height_in_pixels)
        self._root = screen.root

    def move(self, dx: int, dy: int) -> None:
        # XTest relative motion (detail True): one request, no round trip. The server adds the offset to where the
        # pointer is when it processes it (so a real mouse's moves in between are kept) and clips it to the
        # screen; since X.Org 1.7 the XTest device's relative motion gets no pointer acceleration (Xext/xtest.c
        # passes no POINTER_ACCELERATE to GetPointerEvents), so the mapper's own curve is what the hand gets.
        # Before, the position was read back first (XQueryPointer): a round trip on the pointer's path.
        self._xtest.fake_input(self.display, self._X.MotionNotify, detail=True, x=_int16(dx), y=_int16(dy))
        self.display.flush()

    def move_to(self, x: int, y: int) -> None:
        self._xtest.fake_input(self.display, self._X.MotionNotify, x=int(x), y=int(y))
        self.display.flush()

    def press(self, button: str) -> None:
        self._xtest.fake_input(self.display, self._X.ButtonPress, _BUTTON[button])
        self.display.flush()

    def release(self, button: str) -> None:
        self._xtest.fake_input(self.display, self._X.ButtonRelease, _BUTTON[button])
        self.display.flush()

    def screen_size(self):
        return self._size

    def close(self) -> None:
        try:
            # the moves are requests without replies: wait until the server has done them all, so the pointer is
            # where the last one put it once the daemon has stopped (a replay, a script reading it back)
            self.display.sync()
            self.display.close()
        except Exception:
            pass
