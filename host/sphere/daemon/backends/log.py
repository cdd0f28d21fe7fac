"""The ``log`` backend: prints what it would do, one line per call (``move dx dy``, ``click left``)."""

from __future__ import annotations

import sys

from sphere.daemon.backends.base import Backend


class LogBackend(Backend):
    name = "log"

    def __init__(self, stream=None, screen_size=None):
        self.stream = stream or sys.stdout
        self._size = screen_size

    def _out(self, text: str) -> None:
        try:
            self.stream.write(text + "\n")
            self.stream.flush()
        except (BrokenPipeError, ValueError):
            pass

    def move(self, dx: int, dy: int) -> None:
        self._out(f"move {dx} {dy}")

    def press(self, button: str) -> None:
        self._out(f"press {button}")

    def release(self, button: str) -> None:
        self._out(f"release {button}")

    def click(self, button: str = "left", count: int = 1) -> None:
        self._out(f"click {button}" + (f" x{count}" if count != 1 else ""))

    def move_to(self, x: int, y: int) -> None:
        self._out(f"move_to {x} {y}")

    def screen_size(self):
        return self._size
