"""Critically damped spring of seed §8 (eq. 8–9): ÿ = f²(y_d − y) − 2f·ẏ, f = 2 / t_smooth.

Used when a filter hands over to pass-through: the output follows the target without a jump. The
closed form y(t) = y_d + ((y₀ − y_d) + (ẏ₀ + f(y₀ − y_d))·t)·e^{−ft} is applied exactly over each step
(per component, with the target held over the step)."""

from __future__ import annotations

import math

from sphere.settings import Param, resolve


class CriticallyDampedSpring:
    NAME = "spring"
    PARAMS = {"t_smooth_s": Param(0.05, "s", 0.001, 10.0, "smoothing time; the spring's rate f = 2 / t_smooth")}
    GRID = {"t_smooth_s": [0.01, 0.02, 0.05]}

    def __init__(self, *args, **kwargs):
        self.t_smooth_s = resolve(self.PARAMS, args, kwargs)["t_smooth_s"]
        self.reset()

    @property
    def f(self) -> float:
        return 2.0 / self.t_smooth_s

    def reset(self, y=None, v=None) -> None:
        self._y = list(y) if y is not None else None
        self._v = list(v) if v is not None else ([0.0] * len(y) if y is not None else None)

    def update(self, target, dt_s: float):
        if self._y is None:
            self.reset(target)
            return tuple(self._y)
        f = self.f
        e = math.exp(-f * dt_s)
        for i, yd in enumerate(target):
            d0 = self._y[i] - yd
            c = self._v[i] + f * d0
            self._y[i] = yd + (d0 + c * dt_s) * e
            self._v[i] = (c - f * (d0 + c * dt_s)) * e
        return tuple(self._y)

    def distance(self, target) -> float:
        if self._y is None:
            return 0.0
        return math.sqrt(sum((a - b) ** 2 for a, b in zip(self._y, target)))
