"""A private X server (Xvfb) for benchmarks, and the X pointer read at a high rate through Xlib (ctypes)."""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import shutil
import subprocess
import time

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


class PointerReader:
    """``XQueryPointer`` on the root window through libX11 directly: one round trip to the server (tens of µs),
    without python-xlib's per-request Python work, so the pointer can be read several thousand times a second."""

    def __init__(self, display: str):
        path = ctypes.util.find_library("X11")
        if not path:
            raise XvfbUnavailable("libX11 is not installed (apt-get install libx11-6)")
        x = ctypes.CDLL(path)
        x.XOpenDisplay.restype = ctypes.c_void_p
        x.XOpenDisplay.argtypes = [ctypes.c_char_p]
        x.XDefaultRootWindow.restype = ctypes.c_ulong
        x.XDefaultRootWindow.argtypes = [ctypes.c_void_p]
        ul, i, u = ctypes.c_ulong, ctypes.c_int, ctypes.c_uint
        x.XQueryPointer.argtypes = [ctypes.c_void_p, ul, ctypes.POINTER(ul), ctypes.POINTER(ul), ctypes.POINTER(i),
                                    ctypes.POINTER(i), ctypes.POINTER(i), ctypes.POINTER(i), ctypes.POINTER(u)]
        x.XCloseDisplay.argtypes = [ctypes.c_void_p]
        self._x = x
        self._d = x.XOpenDisplay(display.encode())
        if not self._d:
            raise XvfbUnavailable(f"cannot open X display {display}")
        self._root = x.XDefaultRootWindow(self._d)
        self._w = (ul(), ul(), i(), i(), i(), i(), u())
        self._refs = tuple(ctypes.byref(v) for v in self._w)

    def position(self) -> tuple[int, int]:
        self._x.XQueryPointer(self._d, self._root, *self._refs)
        return self._w[2].value, self._w[3].value

    def close(self) -> None:
        if self._d:
            self._x.XCloseDisplay(self._d)
            self._d = None
