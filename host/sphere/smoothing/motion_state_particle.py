"""``motion-state-particle``: the motion-state filter with the paper's SIR particle filter for fast motion
(its hand filter) instead of pass-through."""

from __future__ import annotations

from sphere.smoothing.motion_state import MotionStateFilter


class MotionStateParticle(MotionStateFilter):
    PARAMS = {**MotionStateFilter.PARAMS}
    PARAMS.pop("fast")
    GRID = {"rest_speed": [0.5, 1.0], "fast_speed": [5.0, 20.0], "particle_process_sigma": [0.05, 0.2]}

    def __init__(self, *args, **kwargs):
        super().__init__(*args, fast="particle", **kwargs)
