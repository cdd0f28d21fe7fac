"""The 1€ filter (Casiez, Roussel, Vogel, CHI 2012): a first-order low-pass whose cutoff rises with
speed, so slow motion is smoothed and fast motion is not delayed.

    cutoff = min_cutoff_hz + beta · |dx/dt (smoothed at d_cutoff_hz)|
    alpha  = 1 / (1 + τ/dt),  τ = 1 / (2π · cutoff)
"""

from __future__ import annotations

import math

from sphere.settings import Param, resolve


def _alpha(cutoff_hz: float, dt_s: float) -> float:
    tau = 1.0 / (2.0 * math.pi * cutoff_hz)
    return 1.0 / (1.0 + tau / dt_s)


class OneEuroFilter:
    NAME = "one-euro"
    PARAMS = {
        "min_cutoff_hz": Param(0.5, "Hz", 0.01, 100.0, "cutoff of the low-pass when the signal is still"),
        "beta": Param(0.3, "1/unit", 0.0, 1000.0, "how fast the cutoff rises with speed (Hz per unit/s; °/s for angles)"),
        "d_cutoff_hz": Param(1.0, "Hz", 0.01, 100.0, "cutoff of the speed estimate"),
    }
    GRID = {"min_cutoff_hz": [0.5, 1.0, 2.0, 4.0], "beta": [0.1, 0.3, 1.0, 3.0], "d_cutoff_hz": [1.0]}

    def __init__(self, *args, **kwargs):
        p = resolve(self.PARAMS, args, kwargs)
        if p["min_cutoff_hz"] <= 0 or p["d_cutoff_hz"] <= 0:
            raise ValueError("min_cutoff_hz and d_cutoff_hz must be > 0")
        self.min_cutoff_hz, self.beta, self.d_cutoff_hz = p["min_cutoff_hz"], p["beta"], p["d_cutoff_hz"]
        self.reset()

    def reset(self) -> None:
        self._x = None
        self._dx = None

    def update(self, x, dt_s: float):
        if self._x is None or dt_s <= 0:
            self._x = list(x)
            self._dx = [0.0] * len(x)
            return tuple(self._x)
        a_d = _alpha(self.d_cutoff_hz, dt_s)
        speed2 = 0.0
        for i, xi in enumerate(x):
            d = (xi - self._x[i]) / dt_s
            self._dx[i] += a_d * (d - self._dx[i])
            speed2 += self._dx[i] * self._dx[i]
        a = _alpha(self.min_cutoff_hz + self.beta * math.sqrt(speed2), dt_s)
        for i, xi in enumerate(x):
            self._x[i] += a * (xi - self._x[i])
        return tuple(self._x)
