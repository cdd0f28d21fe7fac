"""Filters by name, with their default parameters and the grid `sphere bench pointer` tunes over."""

from __future__ import annotations

import itertools

from sphere.smoothing.motion_state import MotionStateFilter
from sphere.smoothing.one_euro import OneEuroFilter
from sphere.smoothing.particle import ParticleFilterAR2


class PassThrough:
    def reset(self) -> None:
        pass

    def update(self, x, dt_s: float):
        return tuple(x)


#: name → (factory, tuning grid: parameter → candidate values)
FILTERS = {
    "none": (PassThrough, {}),
    "one-euro": (
        OneEuroFilter,
        {"min_cutoff_hz": [0.3, 0.6, 1.0, 2.0, 4.0], "beta": [0.0005, 0.002, 0.005, 0.01, 0.03], "d_cutoff_hz": [1.0]},
    ),
    "motion-state": (
        MotionStateFilter,
        {"rest_speed": [40.0, 80.0], "fast_speed": [150.0, 400.0], "rest_q_per_s": [0.1, 0.5, 2.0], "t_smooth_s": [0.02, 0.05]},
    ),
    "motion-state-particle": (
        lambda **kw: MotionStateFilter(fast="particle", **kw),
        {"rest_speed": [40.0, 80.0], "fast_speed": [150.0, 400.0], "rest_q_per_s": [0.5], "particle_process_sigma": [5.0, 20.0], "particle_obs_sigma": [1.0]},
    ),
    "particle": (ParticleFilterAR2, {"process_sigma": [2.0, 10.0, 30.0], "obs_sigma": [1.0, 3.0]}),
}


def make_filter(name: str, **params):
    try:
        factory, _ = FILTERS[name]
    except KeyError:
        raise ValueError(f"unknown filter {name!r}; choose from {', '.join(FILTERS)}") from None
    return factory(**params)


def grid(name: str):
    """Every parameter combination of a filter's tuning grid."""
    _, space = FILTERS[name]
    keys = list(space)
    for values in itertools.product(*(space[k] for k in keys)):
        yield dict(zip(keys, values))
