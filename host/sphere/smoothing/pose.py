"""Any registry filter on a pose: orientation as a quaternion (and a position when a pose source gives one).

A quaternion cannot be filtered component by component, and Euler angles jump at ±180°. The orientation is
turned into a continuous rotation vector instead: each new quaternion's turn from the previous one (in the
earth frame, always the short way, so never more than 180° per sample) is added to a running vector in
degrees. The filter smooths that vector, and the output is the measured quaternion turned by the small
difference between the smoothed and the measured vector (earth frame): it has no wrap-around at all, and
with ``none`` it is the input exactly. Positions, when given, go through a filter of their own
(:mod:`sphere.smoothing.position`: parameters in metres and m/s, never the angle filter's degrees).
"""

from __future__ import annotations

import math

from sphere import quaternion
from sphere.smoothing.registry import POSITION, make_filter


def log_deg(q):
    """Rotation vector (°) of a unit quaternion, the short way round."""
    w, x, y, z = q
    if w < 0:
        w, x, y, z = -w, -x, -y, -z
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12:
        return (0.0, 0.0, 0.0)
    k = math.degrees(2.0 * math.atan2(s, w)) / s
    return (x * k, y * k, z * k)


def exp_deg(v):
    """Unit quaternion of a rotation vector in degrees."""
    a = math.radians(math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]))
    if a < 1e-12:
        return (1.0, 0.0, 0.0, 0.0)
    k = math.sin(a / 2.0) / a * math.pi / 180.0
    return (math.cos(a / 2.0), v[0] * k, v[1] * k, v[2] * k)


class PoseFilter:
    """``update(quat, dt_s, position=None) -> (quat, position)``: the orientation through the registry filter
    ``name`` (``params`` in its units, degrees), the position through ``position`` = (name, params) of
    :mod:`sphere.smoothing.position` (metres)."""

    def __init__(self, name: str = "none", position=("none", None), **params):
        self.name = name
        self.position_name = position[0]
        self._orientation = make_filter(name, **params)
        self._position = POSITION.build(position[0], position[1] or {})
        self.reset()

    def reset(self) -> None:
        self._orientation.reset()
        self._position.reset()
        self._q = None
        self._r = [0.0, 0.0, 0.0]
        self._t_us = None

    def at(self, quat, t_us, position=None, default_dt_s: float = 0.005):
        """:meth:`update` with dt from the samples' device times (µs); the filtered quaternion (and position)."""
        dt = default_dt_s
        if t_us is not None and self._t_us is not None and 0 < t_us - self._t_us < 100_000:
            dt = (t_us - self._t_us) * 1e-6
        self._t_us = t_us
        q, pos = self.update(quat, dt, position)
        return q if position is None else (q, pos)

    def update(self, quat, dt_s: float, position=None):
        q = tuple(float(v) for v in quat)
        if self._q is not None:
            step = log_deg(quaternion.mul(q, quaternion.conj(self._q)))  # earth-frame turn since the last sample
            self._r = [a + b for a, b in zip(self._r, step)]
        self._q = q
        smooth = self._orientation.update(self._r, dt_s)
        out = quaternion.mul(exp_deg([float(a) - b for a, b in zip(smooth, self._r)]), q)
        if out[0] < 0:
            out = tuple(-v for v in out)
        pos = None
        if position is None:  # the position is unknown: when it comes back, its filter starts afresh
            self._position.reset()
        else:
            pos = tuple(float(v) for v in self._position.update(tuple(position), dt_s))
        return out, pos
