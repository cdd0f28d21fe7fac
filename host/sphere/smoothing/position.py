"""Smoothing of the 3-D stream's ``position`` in its own units (metres, m/s), apart from the orientation's.

The orientation filters of :mod:`sphere.smoothing.registry` are tuned for angles: their thresholds are in
degrees and °/s (``tremor`` passes motion from 8 °/s). Applied to a position in metres, a hand's 0.3 m/s
is 0.3 "°/s" to them: every move is smoothed as if it were a tremor, and the 3-D stream lagged the hybrid
tracker by about 25 ms. Positions therefore get filters of their own, with parameters in metres:

- ``none``: the hybrid tracker's estimate as it is (it is already a Kalman filter at the IMU's rate);
- ``one-euro``: the 1€ filter (Casiez et al. 2012) with its speed term in m/s.

``DEFAULT`` and ``one-euro``'s PARAMS defaults are `sphere bench position`'s cross-validated pick: chosen on
rendered BROAD stretches 10:100, 14:120, 16:100, 07:40 (render seed 2), which `sphere hybrid-eval` does not
score; on hybrid-eval's own (10:40, 14:64, 16:40, seed 1) it gives 2.30 mm lateral / 5.88 mm depth RMSE,
lag −0.7 ms, against 2.33 / 5.90 mm, −1 ms unfiltered: a light touch (the rule's targets include "never
more than 1.3× the hybrid's own RMSE on any stretch"; a 0.5 Hz cutoff, the pick without it, lagged slow
motion by 6 ms and gave 1.25× on trial 14's lateral). The pick is at the grid's edge and ties with ``none``
on the train stretches (worst ratio 0.767 against 0.769).
A new position filter = its module (a class with ``NAME``, ``PARAMS``, ``GRID``, ``reset``, ``update``) + one
line in ``POSITION`` of :mod:`sphere.smoothing.registry`.
"""

from __future__ import annotations

from sphere.settings import Param
from sphere.smoothing.one_euro import OneEuroFilter


class PositionOneEuro(OneEuroFilter):
    """The 1€ filter on a position (m): cutoff = min_cutoff_hz + beta · speed (m/s)."""

    NAME = "one-euro"
    PARAMS = {
        "min_cutoff_hz": Param(16.0, "Hz", 0.01, 100.0, "cutoff of the low-pass when the ball is still"),
        "beta": Param(300.0, "Hz per m/s", 0.0, 10000.0, "how fast the cutoff rises with the ball's speed"),
        "d_cutoff_hz": Param(4.0, "Hz", 0.01, 100.0, "cutoff of the speed estimate"),
    }
    GRID = {"min_cutoff_hz": [0.5, 1.0, 2.0, 4.0, 8.0, 16.0], "beta": [0.0, 10.0, 30.0, 100.0, 300.0, 1000.0],
            "d_cutoff_hz": [1.0, 4.0]}
