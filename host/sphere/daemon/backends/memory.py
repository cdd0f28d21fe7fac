"""The ``memory`` backend: keeps what it is told (for tests and the latency benchmark)."""

from __future__ import annotations

import time

from sphere.daemon.backends.base import Backend


class RecordingBackend(Backend):
    """Sums pointer steps into ``x``, ``y``; lists clicks with the position they happened at;
    ``on_call`` (if set) is called with ``time.perf_counter_ns()`` at each call."""

    NAME = "memory"

    def __init__(self, screen_size=(1920, 1080), on_call=None):
        self.x = self.y = 0
        self.moves = 0
        self.clicks: list[tuple[str, tuple[int, int]]] = []
        self.presses: list[str] = []
        self._size = screen_size
        self.on_call = on_call

    def _called(self):
        if self.on_call is not None:
            self.on_call(time.perf_counter_ns())

    def move(self, dx: int, dy: int) -> None:
        self._called()
        self.x += dx
        self.y += dy
        self.moves += 1

    def move_to(self, x: int, y: int) -> None:
        self.x, self.y = x, y

    def press(self, button: str) -> None:
        self._called()
        self.presses.append(button)

    def release(self, button: str) -> None:
        pass

    def click(self, button: str = "left", count: int = 1) -> None:
        self._called()
        for _ in range(count):
            self.clicks.append((button, (self.x, self.y)))

    @property
    def x_at_click(self):
        return [pos[0] for _, pos in self.clicks]

    def screen_size(self):
        return self._size
