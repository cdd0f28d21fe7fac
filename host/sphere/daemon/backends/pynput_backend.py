"""The ``pynput`` backend, for macOS and Windows (on Linux it drives X11 too)."""

from __future__ import annotations

import ctypes
import importlib.util
import sys

from sphere.daemon.backends.base import Backend, BackendLost, BackendUnavailable


class _ClosedDisplay:
    def close(self) -> None:
        pass


class PynputBackend(Backend):
    NAME = "pynput"

    def __init__(self, controller=None):
        if importlib.util.find_spec("pynput") is None:
            raise BackendUnavailable("pynput is not installed: pip install pynput")
        try:
            from pynput import mouse  # optional: pynput (the daemon extra)
        except Exception as e:  # pynput raises ImportError at import when it finds no display server
            raise BackendUnavailable(f"pynput cannot start here: {str(e).splitlines()[0]}") from None
        self._buttons = {"left": mouse.Button.left, "right": mouse.Button.right, "middle": mouse.Button.middle}
        try:
            self.mouse = controller or mouse.Controller()
        except Exception as e:
            raise BackendUnavailable(f"pynput cannot start here: {e}") from None
        self._gone: tuple = (BrokenPipeError, ConnectionResetError)
        try:  # on Linux pynput drives X through python-xlib, which says a closed display with its own error
            from Xlib.error import ConnectionClosedError  # optional: python-xlib
            self._gone += (ConnectionClosedError,)
        except ImportError:
            pass

    def _do(self, call, *args) -> None:
        try:
            call(*args)
        except self._gone as e:
            if hasattr(self.mouse, "_display"):  # pynput's X controller closes its display when collected, which
                # raises again on a dead one (a traceback at exit, "Exception ignored in Controller.__del__")
                self.mouse._display = _ClosedDisplay()
            raise BackendLost(f"pynput's display went away ({e}: the session ended or X restarted); start "
                              "sphere-mouse again in the new session") from None

    def move(self, dx: int, dy: int) -> None:
        self._do(self.mouse.move, dx, dy)

    def move_to(self, x: int, y: int) -> None:
        self._do(setattr, self.mouse, "position", (int(x), int(y)))

    def press(self, button: str) -> None:
        self._do(self.mouse.press, self._buttons[button])

    def release(self, button: str) -> None:
        self._do(self.mouse.release, self._buttons[button])

    def click(self, button: str = "left", count: int = 1) -> None:
        self._do(self.mouse.click, self._buttons[button], count)

    def screen_size(self):
        return main_screen_size()


def main_screen_size():
    """(width, height) of the main screen in pixels, by the platform's own means; None if unknown."""
    try:
        if sys.platform == "win32":
            user32 = ctypes.windll.user32
            return (user32.GetSystemMetrics(0), user32.GetSystemMetrics(1))
        if sys.platform == "darwin":
            import Quartz  # optional: pyobjc (pynput installs it on macOS)

            d = Quartz.CGMainDisplayID()
            return (Quartz.CGDisplayPixelsWide(d), Quartz.CGDisplayPixelsHigh(d))
        from Xlib import display  # optional: python-xlib

        dpy = display.Display()
        try:
            s = dpy.screen()
            return (s.width_in_pixels, s.height_in_pixels)
        finally:
            dpy.close()
    except Exception:
        return None
