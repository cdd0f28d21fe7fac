"""``synthetic:turn[:DEG]``: one steady turn about the vertical, then taps — what the 3-D outputs are judged on.

==============  ==============================================================================
 0 – 3 s        still on the desk (the firmware's power-up gyro bias; a client sees no motion)
 3 s            turn left (counter-clockwise seen from above, +z in the sensor frame) DEG degrees
                (default 90) at TURN_DPS = 90 °/s, starting and stopping sharply
 then 1.5 s     still (the client sees the motion stop)
 then           a single knock on the shell (a single tap), 1.6 s still
 then           a double knock (a double tap), still to the end
==============  ==============================================================================

The sensor frame is sphere-mouse's: x towards the screen, y to the left, z up. Knocks are the same
half-sine spikes as ``synthetic:taps`` and ``synthetic:tour`` (4 g along z for 12 ms; the two of a double
knock 0.15 s apart). :func:`turn_timeline` gives the times for tests and benches.
"""

from __future__ import annotations

import numpy as np

from sphere import chips
from sphere.sim.trace import SYNTH_RATE_HZ, Motion, _from_orientation, _integrate

TURN_DPS = 90.0
STILL_BEFORE_S = 3.0
STILL_AFTER_S = 1.5
TAP_PEAK_G = 4.0
TAP_WIDTH_S = 0.012
DOUBLE_TAP_GAP_S = 0.15


def turn_timeline(degrees: float = 90.0) -> dict:
    """Seconds from the start of the trace: the turn's start and end, the single knock, the double knock."""
    start = STILL_BEFORE_S
    end = start + abs(degrees) / TURN_DPS
    tap = end + STILL_AFTER_S
    double = tap + 1.6
    return {"turn_start_s": start, "turn_end_s": end, "single_tap_s": tap,
            "double_tap_s": (double, double + DOUBLE_TAP_GAP_S), "rate_dps": TURN_DPS if degrees >= 0 else -TURN_DPS,
            "degrees": degrees, "min_seconds": double + DOUBLE_TAP_GAP_S + 1.0}


def turn(seconds: float, degrees: float = 90.0, rate_hz: float = SYNTH_RATE_HZ) -> Motion:
    tl = turn_timeline(degrees)
    if seconds < tl["min_seconds"]:
        raise ValueError(f"needs --seconds {tl['min_seconds']:g} or more (the turn, then both taps)")
    n = int(round(seconds * rate_hz))
    t = np.arange(n) / rate_hz
    gyr = np.zeros((n, 3))
    i0, i1 = (int(round(tl[k] * rate_hz)) for k in ("turn_start_s", "turn_end_s"))
    gyr[i0:i1, 2] = np.radians(tl["rate_dps"])
    extra = np.zeros((n, 3))
    for t0 in (tl["single_tap_s"], *tl["double_tap_s"]):
        sel = (t >= t0) & (t < t0 + TAP_WIDTH_S)
        extra[sel, 2] += TAP_PEAK_G * chips.STANDARD_GRAVITY_M_S2 * np.sin(np.pi * (t[sel] - t0) / TAP_WIDTH_S)
    return _from_orientation(_integrate(gyr, rate_hz), gyr, rate_hz, f"turn_{degrees:g}deg", extra_acc=extra)


def synthetic(seconds: float, arg: str) -> Motion:
    """The registry's entry (sphere.sim.trace.SYNTHETIC): ``synthetic:turn`` or ``synthetic:turn:DEG``."""
    try:
        degrees = float(arg) if arg else 90.0
    except ValueError:
        raise ValueError(f"the turn's angle must be a number of degrees, not {arg!r}") from None
    if not 1.0 <= abs(degrees) <= 720.0:
        raise ValueError(f"the turn's angle must be 1 to 720 degrees either way, not {degrees:g}")
    return turn(seconds, degrees)
