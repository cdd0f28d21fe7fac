"""Every smoothing filter by name: the one list the daemon's pointer, the 3-D stream and
`sphere bench pointer` choose from. A new filter = its module (a class with ``NAME``, ``PARAMS``, ``GRID``,
``reset()`` and ``update(x, dt_s) -> y``) + one line here; its ``[smoothing.NAME]`` config section, the
reference and the bench's grid follow from its ``PARAMS`` and ``GRID``.

Each filter's PARAMS defaults are its family's cross-validated pick from `sphere bench pointer` (tuned on
synthetic:hold seeds 1–3 and BROAD trial 05; the figures it prints are on other seeds and trials), except
``tiered``, which keeps the settings the daemon ran before the registry."""

from __future__ import annotations

from sphere.settings import Registry, UnknownComponent

#: name → "module:Class" (imported when first used); config section [smoothing.NAME]
REGISTRY = Registry("smoothing", {
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
}, label="smoothing filter")

#: the filter names (the registry's keys)
FILTERS = REGISTRY.entries

DEFAULT = "tremor"

#: The 3-D stream's position filters, in metres (sphere.smoothing.position says why apart from the angles'):
#: name → "module:Class"; config section [position_smoothing.NAME], chosen by ``[stream] position_smoothing``.
POSITION = Registry("position_smoothing", {
    "none": "sphere.smoothing.passthrough:PassThrough",
    "one-euro": "sphere.smoothing.position:PositionOneEuro",
}, label="position smoothing")

POSITION_DEFAULT = "one-euro"

UnknownFilter = UnknownComponent


def filter_class(name: str):
    return REGISTRY.load(name)


def params(name: str) -> dict:
    """The filter's parameters: name → sphere.settings.Param (default, unit, range, meaning)."""
    return REGISTRY.params(name)


def make_filter(name: str, **values):
    """A new filter by name; ``values`` override the defaults (ValueError says what is wrong)."""
    return filter_class(name)(**values)


def grid(name: str):
    """Every parameter combination of a filter's tuning grid (one empty setting when it has none)."""
    return iter(REGISTRY.grid(name))
