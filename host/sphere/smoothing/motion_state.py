"""The motion-state filter of seed §8: the filter is chosen by speed, with hysteresis.

- rest  (speed < rest_speed):  constant-model Kalman filter (the signal is held steady);
- slow  (rest_speed … fast_speed): windowed intrinsic curve smoothing (m samples late);
- fast  (≥ fast_speed): pass-through — or, for manoeuvring hand motion, the SIR particle filter.

A state is entered above ``threshold·(1 + hysteresis)`` and left below ``threshold·(1 − hysteresis)``.
Every change of state hands over through the critically damped spring (f = 2 / t_smooth) so that
nothing jumps. The spring acts on the *offset* between the last output and the new filter's output
(target 0, starting with the offset's rate), so it removes the jump in about t_smooth without trailing
a moving target (a spring pulled along a ramp would lag it by t_smooth for as long as the ramp lasts);
it lets go once the offset is below ``settle``. Speed is the norm of the signal's rate, smoothed with time constant ``speed_tau_s``.
"""

from __future__ import annotations

import math

from sphere.smoothing.curve import WindowedCurveSmoother
from sphere.smoothing.kalman_rest import ConstantKalman
from sphere.settings import Param, resolve
from sphere.smoothing.particle import ParticleFilterAR2
from sphere.smoothing.spring import CriticallyDampedSpring

REST, SLOW, FAST = "rest", "slow", "fast"


class MotionStateFilter:
    NAME = "motion-state"
    FAST_FILTER = "pass"  # what fast motion gets when PARAMS has no `fast` (a subclass fixes it)
    PARAMS = {
        "rest_speed": Param(2.0, "unit/s", 1e-6, 1e6, "below this speed the signal is at rest (constant Kalman)"),
        "fast_speed": Param(5.0, "unit/s", 1e-6, 1e6, "from this speed the motion is fast (pass or particle)"),
        "hysteresis": Param(0.3, "", 0.0, 0.99, "a state is entered above threshold·(1+h), left below threshold·(1−h)"),
        "speed_tau_s": Param(0.02, "s", 0.0, 10.0, "time constant of the speed estimate"),
        "rest_q_per_s": Param(0.01, "unit²/s", 0.0, 1e6, "the rest Kalman filter's process variance per second"),
        "rest_r": Param(0.0001, "unit²", 1e-12, 1e6, "the rest Kalman filter's measurement variance"),
        "slow_m": Param(2, "samples", 2, 50, "the curve smoother's delay m when slow", integer=True),
        "fast": Param("pass", "", 0, 0, "`pass` or `particle` (the SIR particle filter) when fast", choices=("pass", "particle")),
        "particle_process_sigma": Param(0.1, "unit", 1e-9, 1e6, "the particle filter's model noise per sample"),
        "particle_obs_sigma": Param(0.05, "unit", 1e-9, 1e6, "the particle filter's observation σ"),
        "t_smooth_s": Param(0.02, "s", 0.001, 10.0, "the handover spring's smoothing time"),
        "settle": Param(0.001, "unit", 0.0, 1e6, "the spring lets go once the offset is below this"),
    }
    GRID = {"rest_speed": [0.5, 1.0, 2.0], "fast_speed": [5.0, 20.0], "rest_q_per_s": [0.001, 0.01, 0.1], "t_smooth_s": [0.02, 0.05]}

    def __init__(self, *args, **kwargs):
        p = resolve(self.PARAMS, args, kwargs)
        rest_speed, fast_speed, hysteresis = p["rest_speed"], p["fast_speed"], p["hysteresis"]
        if not 0 < rest_speed < fast_speed:
            raise ValueError("need 0 < rest_speed < fast_speed")
        self.rest_speed, self.fast_speed, self.hysteresis = rest_speed, fast_speed, hysteresis
        self.speed_tau_s, self.settle = p["speed_tau_s"], p["settle"]
        self._rest = ConstantKalman(q_per_s=p["rest_q_per_s"], r=p["rest_r"])
        self._slow = WindowedCurveSmoother(m=p["slow_m"])
        self._fast = (ParticleFilterAR2(process_sigma=p["particle_process_sigma"], obs_sigma=p["particle_obs_sigma"])
                      if p.get("fast", self.FAST_FILTER) == "particle" else None)
        self._spring = CriticallyDampedSpring(t_smooth_s=p["t_smooth_s"])
        self.reset()

    def reset(self) -> None:
        self.state = REST
        self._last_x = None
        self._speed = 0.0
        self._out = None
        self._out_v = None
        self._handover = False
        self._pending_handover = False
        self._last_target = None
        self._rest.reset()
        self._slow.reset()
        if self._fast is not None:
            self._fast.reset()
        self._spring.reset()

    def _next_state(self) -> str:
        s, h = self._speed, self.hysteresis
        lo, hi = self.rest_speed, self.fast_speed
        if self.state == REST:
            return FAST if s > hi * (1 + h) else SLOW if s > lo * (1 + h) else REST
        if self.state == SLOW:
            return FAST if s > hi * (1 + h) else REST if s < lo * (1 - h) else SLOW
        return REST if s < lo * (1 - h) else SLOW if s < hi * (1 - h) else FAST

    def update(self, x, dt_s: float):
        x = tuple(float(v) for v in x)
        if self._last_x is not None and dt_s > 0:
            rate = math.sqrt(sum((a - b) ** 2 for a, b in zip(x, self._last_x))) / dt_s
            k = dt_s / (self.speed_tau_s + dt_s)
            self._speed += k * (rate - self._speed)
        self._last_x = x
        state = self._next_state()
        if state != self.state:
            self.state = state
            if state == REST:
                self._rest.reset(self._out if self._out is not None else x)
            elif state == SLOW:
                self._slow.reset()
            elif self._fast is not None:
                self._fast.reset()
            self._pending_handover = self._out is not None
        if self.state == REST:
            target = self._rest.update(x, dt_s)
        elif self.state == SLOW:
            target = self._slow.update(x, dt_s)
        else:
            target = self._fast.update(x, dt_s) if self._fast is not None else x
        if self._pending_handover:
            self._pending_handover = False
            offset = [a - b for a, b in zip(self._out, target)]
            if self._last_target is not None and self._out_v is not None and dt_s > 0:
                offset_v = [v - (a - b) / dt_s for v, a, b in zip(self._out_v, target, self._last_target)]
            else:
                offset_v = [0.0] * len(offset)
            self._spring.reset(offset, offset_v)
            self._handover = True
        if self._handover:
            off = self._spring.update([0.0] * len(target), dt_s)
            y = tuple(t + o for t, o in zip(target, off))
            if math.sqrt(sum(o * o for o in off)) < self.settle:
                self._handover = False
        else:
            y = target
        self._last_target = target
        if self._out is not None and dt_s > 0:
            self._out_v = [(a - b) / dt_s for a, b in zip(y, self._out)]
        self._out = tuple(y)
        return self._out
