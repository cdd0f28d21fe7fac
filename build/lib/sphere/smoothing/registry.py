"""Every smoothing filter by name: the one list the daemon's pointer, the 3-D stream and
`sphere bench pointer` choose from. A new filter = its module (a class with ``PARAMS``, ``GRID``,
``reset()`` and ``update(x, dt_s) -> y``) + one line here.

Each filter's PARAMS defaults are its family's cross-validated pick from `sphere bench pointer` (tuned on
synthetic:hold seeds 1–3 and BROAD trial 05; the figures it prints are on other seeds and trials), except
``tiered``, which keeps the settings the daemon ran before the registry."""

from __future__ import annotations

import itertools

from sphere.lazy import load

#: name → "module:Class" (imported when first used)
FILTERS = {
    "none": "sphere.smoothing.passthrough:PassThrough",
    "tremor": "sphere.smoothing.tremor:TremorFilter",
    "tiered": "sphere.smoothing.tiered:TieredSmoothing",
    "one-euro": "sphere.smoothing.one_euro:OneEuroFilter",
    "constant-kalman": "sphere.smoothing.kalman_rest:ConstantKalman",
    "curve": "sphere.smoothing.curve:WindowedCurveSmoother",
    "bilateral": "sphere.smoothing.bilateral:BilateralAngleFilter",
    "spring": "sphere.smoothing.spring:CriticallyDampedSpring",
    "particle": "sphere.smoothing.particle:ParticleFilterAR2",
    "motion-state": "sphere.smoothing.motion_state:MotionStateFilter",
    "motion-state-particle": "sphere.smoothing.motion_state_particle:MotionStateParticle",
}

DEFAULT = "tremor"


class UnknownFilter(ValueError):
    pass


def filter_class(name: str):
    try:
        spec = FILTERS[name]
    except KeyError:
        raise UnknownFilter(f"unknown smoothing filter {name!r}; choose from {', '.join(FILTERS)}") from None
    return load(spec)


def params(name: str) -> dict:
    """The filter's parameters: name → sphere.smoothing.params.Param (default, unit, range, meaning)."""
    return dict(filter_class(name).PARAMS)


def make_filter(name: str, **values):
    """A new filter by name; ``values`` override the defaults (ValueError says what is wrong)."""
    return filter_class(name)(**values)


def grid(name: str):
    """Every parameter combination of a filter's tuning grid (one empty setting when it has none)."""
    space = filter_class(name).GRID
    keys = list(space)
    for values in itertools.product(*(space[k] for k in keys)):
        yield dict(zip(keys, values))
