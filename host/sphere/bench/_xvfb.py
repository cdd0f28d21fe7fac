"""A private X server (Xvfb) for benchmarks, and the X pointer read back: each move as the server reports it
(libX11's MotionNotify, through ctypes), read at a high rate through libX11, or sampled in a thread with python-xlib."""

from __future__ import annotations

import ctypes
import math
import os
import select
import shutil
import subprocess
import threading
import time

from sphere.daemon.backends.xlib_ctypes import XLibraryMissing, libx11
from sphere.errors import SphereError


class XvfbUnavailable(SphereError):
    """Xvfb is not installed or did not start; the message says what to do."""


class Xvfb:
    """``Xvfb -displayfd``: the server picks a free display number and writes it to the pipe."""

    def __init__(self, width: int = 1920, height: int = 1080, depth: int = 24, timeout_s: float = 15.0):
        if shutil.which("Xvfb") is None:
            raise XvfbUnavailable("Xvfb is not installed (apt-get install xvfb)")
        r, w = os.pipe()
        self.proc = subprocess.Popen(
            ["Xvfb", "-displayfd", str(w), "-screen", "0", f"{width}x{height}x{depth}", "-nolisten", "tcp", "-noreset"],
            pass_fds=(w,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(w)
        number = b""
        deadline = time.monotonic() + timeout_s
        while not number.endswith(b"\n") and time.monotonic() < deadline:
            chunk = os.read(r, 16)
            if not chunk:
                break
            number += chunk
        os.close(r)
        if not number.strip():
            self.close()
            raise XvfbUnavailable("Xvfb did not start")
        self.display = f":{number.decode().strip()}"

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _libx11():
    try:
        return libx11()
    except XLibraryMissing as e:
        raise XvfbUnavailable(str(e)) from None


class PointerReader:
    """``XQueryPointer`` on the root window through libX11 directly: one round trip to the server (tens of µs),
    without python-xlib's per-request Python work, so the pointer can be read several thousand times a second."""

    def __init__(self, display: str):
        x = _libx11()
        self._x = x
        self._d = x.XOpenDisplay(display.encode())
        if not self._d:
            raise XvfbUnavailable(f"cannot open X display {display}")
        self._root = x.XDefaultRootWindow(self._d)
        ul, i, u = ctypes.c_ulong, ctypes.c_int, ctypes.c_uint
        self._w = (ul(), ul(), i(), i(), i(), i(), u())
        self._refs = tuple(ctypes.byref(v) for v in self._w)

    def position(self) -> tuple[int, int]:
        self._x.XQueryPointer(self._d, self._root, *self._refs)
        return self._w[2].value, self._w[3].value

    def close(self) -> None:
        if self._d:
            self._x.XCloseDisplay(self._d)
            self._d = None


class _XMotionEvent(ctypes.Structure):
    """Xlib's XMotionEvent (X.h / Xlib.h), the fields up to the ones read here."""
    _fields_ = [("type", ctypes.c_int), ("serial", ctypes.c_ulong), ("send_event", ctypes.c_int),
                ("display", ctypes.c_void_p), ("window", ctypes.c_ulong), ("root", ctypes.c_ulong),
                ("subwindow", ctypes.c_ulong), ("time", ctypes.c_ulong), ("x", ctypes.c_int), ("y", ctypes.c_int),
                ("x_root", ctypes.c_int), ("y_root", ctypes.c_int), ("state", ctypes.c_uint),
                ("is_hint", ctypes.c_char), ("same_screen", ctypes.c_int)]


class _XEvent(ctypes.Union):
    """Xlib's XEvent: a union padded to 24 longs."""
    _fields_ = [("type", ctypes.c_int), ("xmotion", _XMotionEvent), ("pad", ctypes.c_long * 24)]


#: X.h: the event type and the input mask of pointer motion
MOTION_NOTIFY = 6
POINTER_MOTION_MASK = 1 << 6


class PointerEvents(PointerReader):
    """Every move of the X pointer as the server reports it: ``MotionNotify`` selected on the root window (any number
    of clients may select it; on a bare Xvfb the root is the window under the pointer), so the server sends each
    move when it makes it, XTest's included, and nothing needs to ask. :meth:`wait` blocks on the connection's
    socket; the time it returns is when the move reached this client."""

    def __init__(self, display: str):
        super().__init__(display)
        self._x.XSelectInput(self._d, self._root, POINTER_MOTION_MASK)
        self._x.XSync(self._d, 0)
        self._fd = self._x.XConnectionNumber(self._d)
        self._event = _XEvent()

    def wait(self, timeout_s: float) -> bool:
        """Whether the server has sent something within ``timeout_s`` (or it is queued already)."""
        if self._x.XPending(self._d):
            return True
        return bool(select.select([self._fd], [], [], timeout_s)[0])

    def moves(self) -> list[tuple[int, int]]:
        """The pointer's position after each move reported since the last call (events that are not motion are
        dropped)."""
        out = []
        ev = self._event
        while self._x.XPending(self._d):
            self._x.XNextEvent(self._d, ctypes.byref(ev))
            if ev.type == MOTION_NOTIFY:
                out.append((ev.xmotion.x_root, ev.xmotion.y_root))
        return out


class PointerSampler:
    """The X pointer read as fast as the server answers (~1 kHz), with perf_counter times. A pointer that comes
    near the screen's edge is put back to the middle under a server grab (no move of the daemon's can fall
    between the read and the warp) and the offset is added to every later sample, so a runaway is measured
    whole instead of stopping at the edge. ``recentre=False``: the pointer is neither moved at the start nor
    put back (it stays where the caller put it; the run must then stay on the screen)."""

    def __init__(self, display_name: str, start=(4096, 4096), margin: int = 200, recentre: bool = True):
        from Xlib import display  # optional dependency: the daemon extra (python-xlib)

        self.d = display.Display(display_name)
        self.root = self.d.screen().root
        self.start = start
        self.margin = margin
        self.recentre = recentre
        self.size = (self.d.screen().width_in_pixels, self.d.screen().height_in_pixels)
        self.samples: list[tuple[float, int, int]] = []
        self.warps = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        if recentre:
            self.root.warp_pointer(*start)
            self.d.sync()

    def _loop(self):
        ox = oy = 0
        m, (w, h) = self.margin, self.size
        warp = None  # (time, dx, dy) of the last warp
        last = None
        while not self._stop.is_set():
            p = self.root.query_pointer()
            now = time.perf_counter()
            x, y = p.root_x, p.root_y
            if warp is not None and last is not None and now - warp[0] < 0.2:
                # the x11 backend moves to (its read of the pointer + step): a read made before the warp undoes
                # it, and the pointer is back near the edge; the offset goes with it
                jx, jy = x + ox - last[0], y + oy - last[1]
                if math.hypot(jx - warp[1], jy - warp[2]) < 0.3 * math.hypot(warp[1], warp[2]):
                    ox -= warp[1]
                    oy -= warp[2]
                    warp = None
            if self.recentre and not (m < x < w - m and m < y < h - m):
                self.d.grab_server()
                p = self.root.query_pointer()
                x, y = p.root_x, p.root_y
                self.root.warp_pointer(*self.start)
                self.d.ungrab_server()
                self.d.sync()
                last = (x + ox, y + oy)
                self.samples.append((time.perf_counter(), *last))
                warp = (time.perf_counter(), x - self.start[0], y - self.start[1])
                ox += warp[1]
                oy += warp[2]
                self.warps += 1
                continue
            last = (x + ox, y + oy)
            self.samples.append((now, *last))
            time.sleep(0.0008)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join(2)
        self.d.close()
