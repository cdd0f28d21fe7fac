"""Per-sample smoothing filters against jitter (seed digest §8, and the 1€ filter).

Every filter here has the same shape: ``update(x, dt_s) -> y`` for one sample of a vector signal
(pointer position in px, angles in degrees, angular rates …) and ``reset()``. They hold no I/O and are
driven identically by the daemon and by `sphere bench pointer`.
"""

from sphere.smoothing.one_euro import OneEuroFilter
from sphere.smoothing.kalman_rest import ConstantKalman
from sphere.smoothing.spring import CriticallyDampedSpring
from sphere.smoothing.curve import WindowedCurveSmoother
from sphere.smoothing.bilateral import BilateralAngleFilter
from sphere.smoothing.particle import ParticleFilterAR2
from sphere.smoothing.motion_state import MotionStateFilter
from sphere.smoothing.registry import FILTERS, make_filter

__all__ = [
    "OneEuroFilter",
    "ConstantKalman",
    "CriticallyDampedSpring",
    "WindowedCurveSmoother",
    "BilateralAngleFilter",
    "ParticleFilterAR2",
    "MotionStateFilter",
    "FILTERS",
    "make_filter",
]
