"""``tiered``: JoyShockMapper's soft tiered smoothing (what `sphere-mouse` ran before the registry).

Motion slower than ``smoothing_dps`` is averaged over ``smoothing_time_s`` (fully below half of it,
blended up to it); faster motion passes untouched. It works on the rate: the rate is taken from
successive positions, the slow part is averaged, and the output position is its integral.
"""

from __future__ import annotations

import math
from collections import deque

from sphere.settings import Param, resolve


class TieredSmoothing:
    NAME = "tiered"
    PARAMS = {
        "smoothing_dps": Param(8.0, "°/s", 0.0, 1000.0, "motion slower than this is smoothed (fully below half of it); 0 = off"),
        "smoothing_time_s": Param(0.06, "s", 0.005, 1.0, "averaging window of the smoothing"),
    }
    GRID = {"smoothing_dps": [4.0, 8.0, 16.0], "smoothing_time_s": [0.03, 0.06, 0.12]}

    def __init__(self, *args, **kwargs):
        p = resolve(self.PARAMS, args, kwargs)
        self.smoothing_dps, self.smoothing_time_s = p["smoothing_dps"], p["smoothing_time_s"]
        self.reset()

    def reset(self) -> None:
        self._last = None
        self._out = None
        self._buf: deque = deque()
        self._sum = None

    def update(self, x, dt_s: float):
        x = tuple(float(v) for v in x)
        if self._last is None or dt_s <= 0:
            self._last, self._out = x, list(x)
            self._sum = [0.0] * len(x)
            return x
        v = [(a - b) / dt_s for a, b in zip(x, self._last)]
        self._last = x
        if self.smoothing_dps > 0:
            hi = self.smoothing_dps
            lo = 0.5 * hi
            mag = math.sqrt(sum(c * c for c in v))
            direct = 0.0 if mag <= lo else 1.0 if mag >= hi else (mag - lo) / (hi - lo)
            part = [c * (1.0 - direct) for c in v]
            n = max(1, int(round(self.smoothing_time_s / dt_s)))
            self._buf.append(part)
            for i, c in enumerate(part):
                self._sum[i] += c
            while len(self._buf) > n:
                for i, c in enumerate(self._buf.popleft()):
                    self._sum[i] -= c
            k = len(self._buf)
            v = [c * direct + s / k for c, s in zip(v, self._sum)]
        for i, c in enumerate(v):
            self._out[i] += c * dt_s
        return tuple(self._out)
