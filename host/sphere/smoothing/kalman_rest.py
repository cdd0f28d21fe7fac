"""The constant-model Kalman filter of seed §8 (eq. 2–4) for a signal at rest: S_t = S_{t−1} + w,
T_t = S_t + n. Per component, with process variance q and measurement variance r (per second of q, so
the behaviour does not depend on the sample rate)."""

from __future__ import annotations


class ConstantKalman:
    def __init__(self, q_per_s: float = 1.0, r: float = 1.0):
        if q_per_s < 0 or r <= 0:
            raise ValueError("q_per_s must be ≥ 0 and r > 0")
        self.q_per_s, self.r = q_per_s, r
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
