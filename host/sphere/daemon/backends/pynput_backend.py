"""The ``pynput`` backend, for macOS and Windows (on Linux it drives X11 too)."""

from __future__ import annotations

import ctypes
import importlib.util
import sys

from sphere.daemon.backends.base import Backend, BackendUnavailable


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

    def move(self, dx: int, dy: int) -> None:
        self.mouse.move(dx, dy)

    def move_to(self, x: int, y: int) -> None:
        self.mouse.position = (int(x), int(y))

    def press(self, button: str) -> None:
        self.mouse.press(self._buttons[button])

    def release(self, button: str) -> None:
        self.mouse.release(self._buttons[button])

    def click(self, button: str = "left", count: int = 1) -> None:
        self.mouse.click(self._buttons[button], count)

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
