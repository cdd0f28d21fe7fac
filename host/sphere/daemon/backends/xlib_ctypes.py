"""libX11 and libXtst called through ctypes: the X11 backend's moves, and the benches' pointer reads and watch.

python-xlib builds each request in Python. The C libraries do it in microseconds: ``sphere bench latency`` measures
the port → pointer path with no daemon work in it (its "host stage's floor") through each library, and on a 2-core
virtual machine, idle, got 0.16 ms median through libXtst against 0.36 ms through python-xlib. ``libX11.so.6`` and ``libXtst.so.6`` (Debian: libx11-6, libxtst6) come with every
X desktop; where either is missing the x11 backend uses python-xlib instead.

Xlib's default handler ends the process on a lost connection (the X server stopped, the session ended): the
backend installs :func:`XSetIOErrorExitHandler` (libX11 ≥ 1.7) so that the connection is marked lost instead, and
the next call raises :class:`XConnectionLost`.
"""

from __future__ import annotations

import ctypes
import ctypes.util

from sphere.daemon.backends.base import BackendLost
from sphere.errors import SphereError


class XLibraryMissing(SphereError, OSError):
    """libX11 or libXtst is not installed."""


class XConnectionLost(BackendLost, ConnectionError):
    """The X server closed the connection."""


def lost_display(name: str) -> XConnectionLost:
    """The one line for a display that went away."""
    return XConnectionLost(f"X display {name} went away (the X server closed the connection: the session ended or X "
                           "restarted); start sphere-mouse again in the new session")


_cache: dict[str, ctypes.CDLL] = {}


def _load(name: str, package: str) -> ctypes.CDLL:
    if name not in _cache:
        path = ctypes.util.find_library(name)
        if not path:
            raise XLibraryMissing(f"lib{name} is not installed (apt-get install {package})")
        _cache[name] = ctypes.CDLL(path)
    return _cache[name]


def libx11() -> ctypes.CDLL:
    """libX11 with the signatures used here."""
    x = _load("X11", "libx11-6")
    if getattr(x, "_sphere_typed", False):
        return x
    vp, ul, i, u = ctypes.c_void_p, ctypes.c_ulong, ctypes.c_int, ctypes.c_uint
    x.XOpenDisplay.restype = vp
    x.XOpenDisplay.argtypes = [ctypes.c_char_p]
    x.XDefaultRootWindow.restype = ul
    x.XDefaultRootWindow.argtypes = [vp]
    x.XQueryPointer.argtypes = [vp, ul, ctypes.POINTER(ul), ctypes.POINTER(ul), ctypes.POINTER(i),
                                ctypes.POINTER(i), ctypes.POINTER(i), ctypes.POINTER(i), ctypes.POINTER(u)]
    x.XCloseDisplay.argtypes = [vp]
    x.XSelectInput.argtypes = [vp, ul, ctypes.c_long]
    x.XConnectionNumber.argtypes = [vp]
    x.XPending.argtypes = [vp]
    x.XNextEvent.argtypes = [vp, vp]
    x.XSync.argtypes = [vp, i]
    x.XFlush.argtypes = [vp]
    x.XDefaultScreen.argtypes = [vp]
    x.XDisplayWidth.argtypes = [vp, i]
    x.XDisplayHeight.argtypes = [vp, i]
    x._sphere_typed = True
    return x


def libxtst() -> ctypes.CDLL:
    """libXtst with the signatures used here."""
    t = _load("Xtst", "libxtst6")
    if getattr(t, "_sphere_typed", False):
        return t
    vp, i, ul = ctypes.c_void_p, ctypes.c_int, ctypes.c_ulong
    t.XTestQueryExtension.argtypes = [vp, ctypes.POINTER(i), ctypes.POINTER(i), ctypes.POINTER(i), ctypes.POINTER(i)]
    t.XTestFakeRelativeMotionEvent.argtypes = [vp, i, i, ul]
    t.XTestFakeMotionEvent.argtypes = [vp, i, i, i, ul]
    t.XTestFakeButtonEvent.argtypes = [vp, ctypes.c_uint, i, ul]
    t._sphere_typed = True
    return t


_IO_HANDLER = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p)
_IO_EXIT_HANDLER = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p)
_lost: set[int] = set()  # displays whose connection was lost (by address)


@_IO_HANDLER
def _on_io_error(display):  # instead of Xlib's default, which prints and ends the process
    _lost.add(display)
    return 0


@_IO_EXIT_HANDLER
def _on_io_error_exit(display, _data):  # called next: returning marks the display dead instead of exit(1)
    _lost.add(display)


class XTest:
    """One connection to the X server for XTest fake input: relative and absolute motion, buttons. Each call sends
    its request and flushes (no reply awaited); :meth:`sync` waits until the server has done them all."""

    def __init__(self, display: str):
        x, t = libx11(), libxtst()
        self._x, self._t = x, t
        self.name = display
        self._d = x.XOpenDisplay(display.encode())
        if not self._d:
            raise ConnectionRefusedError(f"cannot connect to X display {display}")
        if hasattr(x, "XSetIOErrorExitHandler"):  # libX11 >= 1.7: a lost server is an exception, not an exit
            x.XSetIOErrorHandler.argtypes = [_IO_HANDLER]
            x.XSetIOErrorHandler.restype = ctypes.c_void_p
            x.XSetIOErrorHandler(_on_io_error)
            x.XSetIOErrorExitHandler.argtypes = [ctypes.c_void_p, _IO_EXIT_HANDLER, ctypes.c_void_p]
            x.XSetIOErrorExitHandler(self._d, _on_io_error_exit, None)
        n = ctypes.c_int()
        if not t.XTestQueryExtension(self._d, *(ctypes.byref(ctypes.c_int()) for _ in range(3)), ctypes.byref(n)):
            x.XCloseDisplay(self._d)
            self._d = None
            raise LookupError(f"X display {display} has no XTEST extension")
        screen = x.XDefaultScreen(self._d)
        self.size = (x.XDisplayWidth(self._d, screen), x.XDisplayHeight(self._d, screen))

    def _check(self) -> None:
        if self._d is None or self._d in _lost:
            raise lost_display(self.name)

    def move(self, dx: int, dy: int) -> None:
        self._check()
        self._t.XTestFakeRelativeMotionEvent(self._d, dx, dy, 0)
        self._x.XFlush(self._d)
        self._check()

    def move_to(self, x: int, y: int) -> None:
        self._check()
        self._t.XTestFakeMotionEvent(self._d, -1, x, y, 0)  # -1: the screen the pointer is on
        self._x.XFlush(self._d)

    def button(self, number: int, down: bool) -> None:
        self._check()
        self._t.XTestFakeButtonEvent(self._d, number, 1 if down else 0, 0)
        self._x.XFlush(self._d)

    def sync(self) -> None:
        self._check()
        self._x.XSync(self._d, 0)

    def close(self) -> None:
        if self._d:
            lost = self._d in _lost
            _lost.discard(self._d)
            if not lost:
                self._x.XCloseDisplay(self._d)
            self._d = None
