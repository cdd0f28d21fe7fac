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
from sphere.smoothing.particle import ParticleFilterAR2
from sphere.smoothing.spring import CriticallyDampedSpring

REST, SLOW, FAST = "rest", "slow", "fast"


class MotionStateFilter:
    def __init__(
        self,
        rest_speed: float = 20.0,
        fast_speed: float = 300.0,
        hysteresis: float = 0.3,
        speed_tau_s: float = 0.02,
        rest_q_per_s: float = 5.0,
        rest_r: float = 1.0,
        slow_m: int = 2,
        fast: str = "pass",
        particle_process_sigma: float = 1.0,
        particle_obs_sigma: float = 1.0,
        t_smooth_s: float = 0.03,
        settle: float = 0.05,
    ):
        if not 0 < rest_speed < fast_speed or not 0 <= hysteresis < 1:
            raise ValueError("need 0 < rest_speed < fast_speed and 0 ≤ hysteresis < 1")
        if fast not in ("pass", "particle"):
            raise ValueError("fast is 'pass' or 'particle'")
        self.rest_speed, self.fast_speed, self.hysteresis = rest_speed, fast_speed, hysteresis
        self.speed_tau_s, self.settle = speed_tau_s, settle
        self._rest = ConstantKalman(rest_q_per_s, rest_r)
        self._slow = WindowedCurveSmoother(slow_m)
        self._fast = ParticleFilterAR2(process_sigma=particle_process_sigma, obs_sigma=particle_obs_sigma) if fast == "particle" else None
        self._spring = CriticallyDampedSpring(t_smooth_s)
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
