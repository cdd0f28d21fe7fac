"""Events (single tap, double tap, free fall) → actions, and the pointer freeze around them.

A knock on the shell jolts the sphere just before the firmware reports the tap, and a toss moves it a
lot before the free fall is seen. So, on such an event, the pointer motion of the last
``*_before_ms`` (device time) is undone first — the click lands where the pointer was aimed — and
the pointer then stays still for ``*_after_ms``. Samples flagged ``tap_active`` never move it.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

CLICK_ACTIONS = {"left_click": "left", "right_click": "right", "middle_click": "middle"}


@dataclass
class Action:
    """One thing to do: ``kind`` is an action name from config.ACTIONS; ``undo`` pixels to move first."""

    kind: str
    event: str
    t_us: int
    undo: tuple[int, int] = (0, 0)


class MotionHistory:
    """The pointer steps sent recently, with their device time, so that some can be undone."""

    def __init__(self, keep_us: int = 3_000_000):
        self.keep_us = keep_us
        self._moves: deque = deque()

    def add(self, t_us: int, dx: int, dy: int) -> None:
        self._moves.append((t_us, dx, dy))
        while self._moves and self._moves[0][0] < t_us - self.keep_us:
            self._moves.popleft()

    def undo_since(self, t_us: int) -> tuple[int, int]:
        """Remove the moves at or after ``t_us``; returns the step that takes them back."""
        ux = uy = 0
        while self._moves and self._moves[-1][0] >= t_us:
            _, dx, dy = self._moves.pop()
            ux -= dx
            uy -= dy
        return ux, uy

    def clear(self) -> None:
        self._moves.clear()


class EventActions:
    """Routes EVENT packets to actions according to the ``[events]`` and ``[freeze]`` settings."""

    def __init__(self, events, freeze):
        self.map = {"single_tap": events.single_tap, "double_tap": events.double_tap, "free_fall": events.free_fall}
        self.single_tap_wait_us = events.single_tap_wait_ms * 1000
        self.freeze = freeze
        self.history = MotionHistory()
        self.frozen_until_us = -1
        self._pending: Action | None = None  # a single tap waiting to see if a double tap follows
        self._last_click_us = None

    def frozen(self, t_us: int | None) -> bool:
        return t_us is not None and t_us < self.frozen_until_us

    def moved(self, t_us: int, dx: int, dy: int) -> None:
        self.history.add(t_us, dx, dy)

    def _freeze_around(self, t_us: int, before_ms: int, after_ms: int) -> tuple[int, int]:
        undo = self.history.undo_since(t_us - before_ms * 1000) if before_ms else (0, 0)
        self.frozen_until_us = max(self.frozen_until_us, t_us + after_ms * 1000)
        return undo

    def on_event(self, name: str, t_us: int) -> list[Action]:
        """The actions for one event, in order. Call :meth:`due` as time passes for delayed single taps."""
        out: list[Action] = []
        f = self.freeze
        if name in ("single_tap", "double_tap"):
            undo = self._freeze_around(t_us, f.tap_before_ms, f.tap_after_ms)
        elif name == "free_fall":
            undo = self._freeze_around(t_us, f.free_fall_before_ms, f.free_fall_after_ms)
        else:
            return out
        kind = self.map.get(name, "none")
        if name == "single_tap" and self.single_tap_wait_us and kind != "none":
            self._pending = Action(kind, name, t_us, undo)
            return out
        if name == "double_tap" and self._pending is not None:
            # the double tap replaces the single tap that was held back
            pu = self._pending.undo
            undo = (undo[0] + pu[0], undo[1] + pu[1])
            self._pending = None
            if kind == "double_click":
                kind = "double_click_full"
        elif name == "double_tap" and kind == "double_click":
            # the first tap already clicked: one more click makes the double click
            single = self.map["single_tap"]
            if single == "left_click" and self._last_click_us is not None and t_us - self._last_click_us < 600_000:
                kind = "second_click"
            else:
                kind = "double_click_full"
        if self._pending is not None:
            out.append(self._pending)
            self._pending = None
        if kind == "none":
            if undo != (0, 0):
                out.append(Action("none", name, t_us, undo))
            return out
        if kind == "left_click":
            self._last_click_us = t_us
        out.append(Action(kind, name, t_us, undo))
        return out

    def due(self, now_us: int | None) -> list[Action]:
        """A held single tap whose wait has passed without a double tap."""
        p = self._pending
        if p is not None and now_us is not None and now_us - p.t_us >= self.single_tap_wait_us:
            self._pending = None
            if p.kind == "left_click":
                self._last_click_us = p.t_us
            return [p]
        return []
