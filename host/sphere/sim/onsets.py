"""``synthetic:onsets``: sharp turns that start at known times, for `sphere bench latency`.

Still for :data:`LEAD_S` (power-up, the gyro's start-up, the host's still-time bias), then every
:data:`PERIOD_S` a turn about the sensor's z axis (yaw with z up: the pointer moves sideways) at
:data:`RATE_DPS` for :data:`TURN_S`, alternately left and right so that the pointer stays on the screen.
Each onset is moved by a seeded offset within one 5 ms sample period, so onsets fall at every phase of
the firmware's sample clock and of the adapter's 1 ms USB frames (a latency figure measured at one phase
only would be a best or a worst case).

The motion is sampled at 1 kHz; the gyro trace keeps that rate (the ITG-3200 model samples it at its
internal 1 kHz, interpolating linearly), so an onset is a ramp from rest to full rate over 1 ms that
starts at the time :func:`onset_times` gives.
"""

from __future__ import annotations

import numpy as np

from sphere.sim.trace import SYNTH_RATE_HZ, Motion, _from_orientation, _integrate

LEAD_S = 3.0
PERIOD_S = 0.4
TURN_S = 0.08
RATE_DPS = 120.0
SAMPLE_PERIOD_S = 0.005
SEED = 27


def onset_times(seconds: float, seed: int = SEED, lead_s: float = LEAD_S, period_s: float = PERIOD_S,
                rate_hz: float = SYNTH_RATE_HZ) -> np.ndarray:
    """Simulated seconds at which each turn starts (the first instant the rate is not zero)."""
    rng = np.random.default_rng(seed)
    starts = np.arange(lead_s, seconds - period_s + 1e-9, period_s)
    jittered = starts + rng.uniform(0.0, SAMPLE_PERIOD_S, len(starts))
    return np.round(jittered * rate_hz) / rate_hz  # on the motion's own 1 ms grid


def onsets(seconds: float, seed: int = SEED, rate_dps: float = RATE_DPS, rate_hz: float = SYNTH_RATE_HZ) -> Motion:
    n = int(round(seconds * rate_hz))
    gyr = np.zeros((n, 3))
    turn = int(round(TURN_S * rate_hz))
    for k, t in enumerate(onset_times(seconds, seed, rate_hz=rate_hz)):
        # sample i holds the rate from i/rate_hz; the model interpolates from the sample before: the ramp
        # begins at t when sample t*rate_hz + 1 is the first at full rate
        i = int(round(t * rate_hz)) + 1
        gyr[i:i + turn, 2] = np.radians(rate_dps) * (1 if k % 2 == 0 else -1)
    return _from_orientation(_integrate(gyr, rate_hz), gyr, rate_hz, "onsets")


def synthetic(seconds: float, arg: str) -> Motion:
    """``synthetic:onsets[:SEED]``."""
    try:
        seed = int(arg) if arg else SEED
    except ValueError:
        raise ValueError(f"the seed must be an integer, not {arg!r}") from None
    return onsets(seconds, seed)
