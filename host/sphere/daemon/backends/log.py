"""The ``log`` backend: prints what it would do, without a display.

Moves are summed and printed once a second (``move +120 -4 px in 200 steps; at +340 -20 from the
start``), so a minute of motion is sixty lines, not twelve thousand; clicks and button presses are
printed as they happen (``click left``), after the moves that came before them.
"""

from __future__ import annotations

import sys
import time

from sphere.daemon.backends.base import Backend


class LogBackend(Backend):
    NAME = "log"

    @classmethod
    def from_settings(cls, settings, stream=None) -> "LogBackend":
        return cls(stream)

    def __init__(self, stream=None, screen_size=None, interval_s: float = 1.0, clock=time.monotonic):
        self.stream = stream or sys.stdout
        self._size = screen_size
        self.interval_s = interval_s
        self._clock = clock
        self._dx = self._dy = self._steps = 0
        self._x = self._y = 0  # where the pointer is, relative to where it was at the start
        self._since = None

    def _out(self, text: str) -> None:
        try:
            self.stream.write(text + "\n")
            self.stream.flush()
        except (BrokenPipeError, ValueError):
            pass

    def flush_moves(self) -> None:
        """Print the moves summed since the last summary (nothing when there were none)."""
        if self._steps:
            self._out(f"move {self._dx:+d} {self._dy:+d} px in {self._steps} steps; "
                      f"at {self._x:+d} {self._y:+d} from the start")
        self._dx = self._dy = self._steps = 0
        self._since = None

    def move(self, dx: int, dy: int) -> None:
        now = self._clock()
        if self._since is None:
            self._since = now
        self._dx += dx
        self._dy += dy
        self._x += dx
        self._y += dy
        self._steps += 1
        if now - self._since >= self.interval_s:
            self.flush_moves()

    def press(self, button: str) -> None:
        self.flush_moves()
        self._out(f"press {button}")

    def release(self, button: str) -> None:
        self.flush_moves()
        self._out(f"release {button}")

    def click(self, button: str = "left", count: int = 1) -> None:
        self.flush_moves()
        self._out(f"click {button}" + (f" x{count}" if count != 1 else ""))

    def move_to(self, x: int, y: int) -> None:
        self.flush_moves()
        self._out(f"move_to {x} {y}")

    def screen_size(self):
        return self._size

    def close(self) -> None:
        self.flush_moves()
