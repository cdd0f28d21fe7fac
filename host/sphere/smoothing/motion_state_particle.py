"""``motion-state-particle``: the motion-state filter with the paper's SIR particle filter for fast motion
(its hand filter) instead of pass-through."""

from __future__ import annotations

from sphere.smoothing.motion_state import MotionStateFilter

_BASE = MotionStateFilter.PARAMS


class MotionStateParticle(MotionStateFilter):
    NAME = "motion-state-particle"
    FAST_FILTER = "particle"
    # the defaults are `sphere bench pointer`'s cross-validated pick for this family
    PARAMS = {k: p for k, p in _BASE.items() if k != "fast"} | {
        "rest_speed": _BASE["rest_speed"].replace(default=0.5),
        "fast_speed": _BASE["fast_speed"].replace(default=20.0),
        "particle_process_sigma": _BASE["particle_process_sigma"].replace(default=0.2),
    }
    GRID = {"rest_speed": [0.5, 1.0], "fast_speed": [5.0, 20.0], "particle_process_sigma": [0.05, 0.2]}
