"""The ``pynput`` backend, for macOS and Windows (on Linux it drives X11 too)."""

from __future__ import annotations

from sphere.daemon.backends.base import Backend, BackendUnavailable


class PynputBackend(Backend):
    name = "pynput"

    def __init__(self, controller=None):
        try:
            from pynput import mouse
        except ImportError:
            raise BackendUnavailable("pynput is not installed: pip install pynput") from None
        except Exception as e:  # pynput fails at import when it finds no display server
            raise BackendUnavailable(f"pynput cannot start here: {e}") from None
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
