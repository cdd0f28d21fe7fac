"""The constant-model Kalman filter of seed §8 (eq. 2–4) for a signal at rest: S_t = S_{t−1} + w,
T_t = S_t + n. Per component, with process variance q and measurement variance r (per second of q, so
the behaviour does not depend on the sample rate)."""

from __future__ import annotations

from sphere.settings import Param, resolve


class ConstantKalman:
    NAME = "constant-kalman"
    PARAMS = {
        "q_per_s": Param(0.001, "unit²/s", 0.0, 1e6, "process variance per second: how fast the held value may move"),
        "r": Param(0.001, "unit²", 1e-12, 1e6, "measurement variance (the jitter's)"),
    }
    GRID = {"q_per_s": [0.001, 0.01, 0.1], "r": [1e-5, 1e-4, 1e-3]}

    def __init__(self, *args, **kwargs):
        p = resolve(self.PARAMS, args, kwargs)
        self.q_per_s, self.r = p["q_per_s"], p["r"]
        self.reset()

    def reset(self, x=None) -> None:
        self._s = list(x) if x is not None else None
        self._p = [self.r] * len(x) if x is not None else None

    def update(self, x, dt_s: float):
        if self._s is None:
            self.reset(x)
            return tuple(self._s)
        q = self.q_per_s * dt_s
        for i, xi in enumerate(x):
            p = self._p[i] + q
            k = p / (p + self.r)
            self._s[i] += k * (xi - self._s[i])
            self._p[i] = (1.0 - k) * p
        return tuple(self._s)
