"""The bilateral filter of seed §8 (eq. 5–7) for Euler angles: each output angle is a weighted mean of
itself and its one neighbour on each side, the weights multiplying a Gaussian of the spatial distance
between the neighbouring positions (σ_c) and a Gaussian of the angle difference (σ_s). Output is one
sample late. Without positions, the spatial term uses the sample distance (1) for both neighbours."""

from __future__ import annotations

import math
from collections import deque

from sphere.settings import Param, resolve


def _wrap_deg(a: float) -> float:
    return (a + 180.0) % 360.0 - 180.0


class BilateralAngleFilter:
    NAME = "bilateral"
    PARAMS = {
        "sigma_c": Param(3.0, "samples", 1e-3, 1e3, "σ_c of the spatial Gaussian (sample distance without positions)"),
        "sigma_s_deg": Param(0.3, "°", 1e-4, 180.0, "σ_s of the Gaussian of the angle difference"),
    }
    GRID = {"sigma_c": [1.0, 3.0], "sigma_s_deg": [0.02, 0.05, 0.1, 0.3]}

    def __init__(self, *args, **kwargs):
        p = resolve(self.PARAMS, args, kwargs)
        self.sigma_c, self.sigma_s_deg = p["sigma_c"], p["sigma_s_deg"]
        self.reset()

    def reset(self) -> None:
        self._angles: deque = deque(maxlen=3)
        self._positions: deque = deque(maxlen=3)

    @property
    def delay_samples(self) -> int:
        return 1

    def update(self, angles_deg, dt_s: float = 0.0, position=None):
        self._angles.append(tuple(angles_deg))
        self._positions.append(tuple(position) if position is not None else None)
        if len(self._angles) < 3:
            return self._angles[-1] if len(self._angles) == 1 else self._angles[0]
        centre_a = self._angles[1]
        centre_p = self._positions[1]
        out = []
        for k in range(len(centre_a)):
            num = den = 0.0
            for j in range(3):
                if centre_p is not None and self._positions[j] is not None:
                    d2 = sum((a - b) ** 2 for a, b in zip(self._positions[j], centre_p))
                else:
                    d2 = float((j - 1) ** 2)
                diff = _wrap_deg(self._angles[j][k] - centre_a[k])
                w = math.exp(-d2 / (2 * self.sigma_c**2) - diff * diff / (2 * self.sigma_s_deg**2))
                num += w * diff
                den += w
            out.append(_wrap_deg(centre_a[k] + num / den))
        return tuple(out)
