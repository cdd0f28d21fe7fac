"""Building a filter from the registry (:mod:`sphere.fusion.registry`, the light table of names, parameters and
grids that the daemon's config reads without numpy): :func:`make` for a stream, :func:`make_for_trial` as
`sphere eval` calls it for a recording (the start-up gyro calibration and the e-compass start for the filters
whose class says ``STARTUP_BIAS``)."""

from __future__ import annotations

import numpy as np

from sphere.fusion.common import ecompass
from sphere.fusion.registry import STARTUP_BIAS_S, filter_class, params
from sphere.settings import Settings


def startup_gyro_bias(gyr_rad_s, dt_s: float, seconds: float = STARTUP_BIAS_S, max_std_rad_s: float = 0.02):
    """Mean gyro over the first ``seconds`` if the sensor was still then (the device's start-up gyro
    calibration); zeros otherwise."""
    n = max(1, int(round(seconds / dt_s)))
    g = np.asarray(gyr_rad_s, dtype=float)[:n]
    if len(g) < n or np.any(g.std(axis=0) > max_std_rad_s):
        return (0.0, 0.0, 0.0)
    return tuple(g.mean(axis=0).tolist())


def make(name: str, dt_s: float | None = None, first_acc=None, first_mag=None, gyro_bias_rad_s=(0.0, 0.0, 0.0),
         **overrides):
    """A fresh filter called ``name`` for a stream with step ``dt_s``; first samples give the initial state.

    ``gyro_bias_rad_s`` (filters with ``STARTUP_BIAS`` only) is the start-up gyro calibration the device
    would apply; ``overrides`` replace the defaults (``sphere eval --cv`` passes its grid points, the daemon
    its ``[orientation.NAME]`` values)."""
    cls = filter_class(name)
    q0 = (1.0, 0.0, 0.0, 0.0)
    if first_acc is not None:
        q0 = ecompass(*map(float, first_acc), *(map(float, first_mag) if first_mag is not None else (0.0, 0.0, 0.0)),
                      frame="NWU")
    s = Settings(getattr(cls, "PARAMS", {}), params(name, **overrides), checked=True)
    return cls.from_settings(s, dt_s=dt_s, q0=q0, gyro_bias_rad_s=gyro_bias_rad_s)


def make_for_trial(name: str, gyr, acc, mag, dt_s: float, **overrides):
    """``make`` as `sphere eval` calls it for a recording: the start-up calibration from its first second and
    the initial orientation from its first sample, for the filters that take them."""
    if not getattr(filter_class(name), "STARTUP_BIAS", False):
        return make(name, dt_s, **overrides)
    return make(name, dt_s, acc[0], None if mag is None else mag[0],
                gyro_bias_rad_s=startup_gyro_bias(gyr, dt_s), **overrides)
