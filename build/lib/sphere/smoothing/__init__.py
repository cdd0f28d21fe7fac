"""Per-sample smoothing filters against jitter and tremor (seed digest §8, the 1€ filter, JoyShockMapper's
tiered smoothing, and a tremor band-stop), all by name from :mod:`sphere.smoothing.registry`.

Every filter has the same shape: ``update(x, dt_s) -> y`` for one sample of a vector signal and
``reset()``, with its parameters (default, unit, range) in ``PARAMS``. They hold no I/O. The daemon's
pointer (:class:`sphere.daemon.pointer.PointerMapper`, on the pointer's angles in degrees), its 3-D
stream (on the pose) and `sphere bench pointer` (which runs the daemon's own packet path) all take them
from the registry, chosen by the config keys ``pointer.smoothing`` and ``stream.smoothing``.
"""

from sphere.smoothing.bilateral import BilateralAngleFilter
from sphere.smoothing.curve import WindowedCurveSmoother
from sphere.smoothing.kalman_rest import ConstantKalman
from sphere.smoothing.motion_state import MotionStateFilter
from sphere.smoothing.one_euro import OneEuroFilter
from sphere.smoothing.particle import ParticleFilterAR2
from sphere.smoothing.registry import DEFAULT, FILTERS, make_filter
from sphere.smoothing.spring import CriticallyDampedSpring
from sphere.smoothing.tiered import TieredSmoothing
from sphere.smoothing.tremor import TremorFilter

__all__ = [
    "OneEuroFilter",
    "ConstantKalman",
    "CriticallyDampedSpring",
    "WindowedCurveSmoother",
    "BilateralAngleFilter",
    "ParticleFilterAR2",
    "MotionStateFilter",
    "TieredSmoothing",
    "TremorFilter",
    "DEFAULT",
    "FILTERS",
    "make_filter",
]
