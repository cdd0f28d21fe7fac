"""SIR particle filter of seed §8 (eq. 1) for fast, manoeuvring motion: 100 particles, a second-order
autoregressive motion model X_t = X̃ + A1(X_{t−1} − X̃) + A2(X_{t−2} − X̃) + B_t, weighted by a Gaussian
likelihood of the raw observation, normalised, resampled (systematic). With A1 = 2, A2 = −1 and X̃ = 0
the model is constant velocity."""

from __future__ import annotations

import numpy as np


class ParticleFilterAR2:
    def __init__(self, particles: int = 100, a1: float = 2.0, a2: float = -1.0, process_sigma: float = 1.0,
                 obs_sigma: float = 1.0, seed: int = 0):
        if particles < 2 or process_sigma <= 0 or obs_sigma <= 0:
            raise ValueError("need ≥ 2 particles and positive sigmas")
        self.particles, self.a1, self.a2 = particles, a1, a2
        self.process_sigma, self.obs_sigma = process_sigma, obs_sigma
        self._seed = seed
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
