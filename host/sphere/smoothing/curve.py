"""Quasi-real-time intrinsic discrete-curve smoothing of seed §8 on a sliding window of n = 2 + m
points: each edge of the polyline is split into its length and its direction (the angles θ, φ of the
edge vector; a unit vector here, which is the same information without angle wrap-around); the
directions are smoothed along the curve while lengths are kept; the vertices are recovered by least
squares from the smoothed edges and the measured points. The estimate is output m samples late."""

from __future__ import annotations

from collections import deque

import numpy as np

from sphere.settings import Param, resolve


class WindowedCurveSmoother:
    NAME = "curve"
    PARAMS = {
        "m": Param(4, "samples", 2, 50, "the output is m samples late; the window holds n = 2 + m points", integer=True),
        "point_weight": Param(0.2, "", 1e-6, 1e6, "weight of the measured points against the smoothed edges"),
        "passes": Param(2, "", 0, 20, "smoothing passes over the edge directions", integer=True),
    }
    GRID = {"m": [2, 4], "point_weight": [0.05, 0.2, 1.0], "passes": [2]}

    def __init__(self, *args, **kwargs):
        p = resolve(self.PARAMS, args, kwargs)
        m = p["m"]
        self.m, self.n = m, 2 + m
        self.point_weight, self.passes = p["point_weight"], p["passes"]
        # least-squares system: w·|p_i − x_i|² + Σ |(p_{i+1} − p_i) − ê_i|²  →  (wI + DᵀD) p = w·x + Dᵀê
        n = self.n
        d = np.zeros((n - 1, n))
        d[np.arange(n - 1), np.arange(n - 1)] = -1.0
        d[np.arange(n - 1), np.arange(1, n)] = 1.0
        self._d = d
        self._solve = np.linalg.inv(self.point_weight * np.eye(n) + d.T @ d)
        self.reset()

    def reset(self) -> None:
        self._window: deque = deque(maxlen=self.n)

    @property
    def delay_samples(self) -> int:
        return self.m

    def update(self, x, dt_s: float = 0.0):
        self._window.append(tuple(float(v) for v in x))
        if len(self._window) < self.n:
            return self._window[0] if len(self._window) <= self.m else self._window[-1 - self.m]
        pts = np.array(self._window)
        edges = np.diff(pts, axis=0)
        lengths = np.linalg.norm(edges, axis=1, keepdims=True)
        dirs = np.divide(edges, lengths, out=np.zeros_like(edges), where=lengths > 1e-12)
        for _ in range(self.passes):  # smooth directions along the curve: [¼, ½, ¼], ends kept
            inner = 0.25 * dirs[:-2] + 0.5 * dirs[1:-1] + 0.25 * dirs[2:]
            norm = np.linalg.norm(inner, axis=1, keepdims=True)
            dirs[1:-1] = np.divide(inner, norm, out=dirs[1:-1].copy(), where=norm > 1e-12)
        smoothed_edges = dirs * lengths
        p = self._solve @ (self.point_weight * pts + self._d.T @ smoothed_edges)
        return tuple(p[self.n - 1 - self.m])
