"""``none``: the signal as it is (the reference every filter is compared with)."""

from __future__ import annotations


class PassThrough:
    NAME = "none"
    PARAMS: dict = {}
    GRID: dict = {}

    def __init__(self, **params):
        if params:
            raise ValueError(f"unknown parameter {next(iter(params))!r}; `none` has no parameters")

    def reset(self) -> None:
        pass

    def update(self, x, dt_s: float):
        return tuple(x)
