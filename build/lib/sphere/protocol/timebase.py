"""Turning the device's wrapping 32-bit microsecond clock into a monotonic count."""

from __future__ import annotations

WRAP_US = 1 << 32


class TimeUnwrapper:
    """Feed successive `t_us` values (u32); get a count that keeps growing across wraps.

    A step backwards of more than half the range is a wrap; a smaller one is kept as it is (the device
    never steps back, but a reordered or restarted stream must not add 71 minutes).
    """

    def __init__(self) -> None:
        self._last: int | None = None
        self._offset = 0

    def reset(self) -> None:
        self._last = None
        self._offset = 0

    def __call__(self, t_us: int) -> int:
        if self._last is not None and t_us < self._last and self._last - t_us > WRAP_US // 2:
            self._offset += WRAP_US
        self._last = t_us
        return t_us + self._offset
