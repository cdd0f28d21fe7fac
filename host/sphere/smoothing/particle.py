"""SIR particle filter of seed §8 (eq. 1) for fast, manoeuvring motion: 100 particles, a second-order
autoregressive motion model X_t = X̃ + A1(X_{t−1} − X̃) + A2(X_{t−2} − X̃) + B_t, weighted by a Gaussian
likelihood of the raw observation, normalised, resampled (systematic). With A1 = 2, A2 = −1 and X̃ = 0
the model is constant velocity."""

from __future__ import annotations

import numpy as np

from sphere.settings import Param, resolve


class ParticleFilterAR2:
    NAME = "particle"
    PARAMS = {
        "particles": Param(100, "", 2, 10000, "number of particles (the paper: 100)", integer=True),
        "a1": Param(2.0, "", -10.0, 10.0, "A1 of the AR(2) motion model (2 with A2 = −1: constant velocity)"),
        "a2": Param(-1.0, "", -10.0, 10.0, "A2 of the AR(2) motion model"),
        "process_sigma": Param(0.1, "unit", 1e-9, 1e6, "σ of the model's noise B_t per sample"),
        "obs_sigma": Param(0.02, "unit", 1e-9, 1e6, "σ of the observation (the jitter)"),
        "seed": Param(0, "", 0, 2**31 - 1, "random seed (runs repeat exactly)", integer=True),
    }
    GRID = {"process_sigma": [0.02, 0.1, 0.5], "obs_sigma": [0.02, 0.1]}

    def __init__(self, *args, **kwargs):
        p = resolve(self.PARAMS, args, kwargs)
        self.particles, self.a1, self.a2 = p["particles"], p["a1"], p["a2"]
        self.process_sigma, self.obs_sigma = p["process_sigma"], p["obs_sigma"]
        self._seed = p["seed"]
        self.reset()

    def reset(self) -> None:
        self._rng = np.random.default_rng(self._seed)
        self._x1 = None  # (P, D) state at t−1
        self._x2 = None  # (P, D) state at t−2

    def update(self, x, dt_s: float = 0.0):
        z = np.asarray(x, dtype=float)
        if self._x1 is None:
            self._x1 = np.tile(z, (self.particles, 1))
            self._x2 = self._x1.copy()
            return tuple(z)
        pred = self.a1 * self._x1 + self.a2 * self._x2
        pred += self._rng.normal(0.0, self.process_sigma, pred.shape)
        d2 = np.sum((pred - z) ** 2, axis=1)
        logw = -0.5 * d2 / self.obs_sigma**2
        w = np.exp(logw - logw.max())
        w /= w.sum()
        estimate = w @ pred
        # systematic resampling
        positions = (self._rng.random() + np.arange(self.particles)) / self.particles
        idx = np.minimum(np.searchsorted(np.cumsum(w), positions), self.particles - 1)
        self._x2 = self._x1[idx]
        self._x1 = pred[idx]
        return tuple(estimate)
