"""``tremor``: takes physiological tremor out of a held sphere's motion by its frequency, and lets
deliberate motion through by its speed.

A hand holding still shakes in a narrow band around 8–12 Hz (physiological tremor) at about 0.1° RMS;
its rate (≈ 6 °/s) is as fast as slow aiming, so speed alone cannot tell them apart — frequency can:

1. **Band-stop.** A cascade of second-order notch filters (RBJ biquads, bilinear transform with the
   frequency pre-warped for the actual sample period) centred in the tremor band removes it. A notch
   passes DC and slow motion with unit gain and delays a slow ramp by only 1 / (Q·2π·f₀) per notch
   (≈ 23 ms at 10 Hz, Q = 0.7), far less than a low-pass that stops 10 Hz as well would.
2. **Rest smoothing by speed.** The intended speed is the rate of the band-stopped signal, averaged
   as a vector over ``speed_tau_s`` (so noise and what is left of the tremor average out); a first-order
   low-pass with the cutoff ``min_cutoff_hz + beta·speed`` (the 1€ filter's rule, Casiez et al. 2012)
   steadies a sphere lying still and leaves aiming speeds nearly undelayed.
3. **Speed gate.** From ``pass_dps`` up the output is the input itself (no lag on fast moves), below
   half of it the filtered signal, blended linearly in between — the output never jumps. While the input
   passes untouched the filters are held at it (their steady state for the current value), so when a
   fast move stops they start from where the pointer is: nothing is left to catch up, nothing rings past
   the stop.

Works per component on any vector (pointer angles, the 3-D stream's rotation vector, positions).

The defaults are `sphere bench pointer`'s cross-validated pick (tuned on synthetic:hold seeds 1–3 and BROAD
trial 05, scored on seeds 11–13 and trials 09, 14).
"""

from __future__ import annotations

import math

from sphere.settings import Param, resolve

_TWO_PI = 2.0 * math.pi


class _Notch:
    """One biquad notch (Audio EQ Cookbook, R. Bristow-Johnson) per component, transposed direct form II."""

    def __init__(self, f0_hz: float, q: float):
        self.f0_hz, self.q = f0_hz, q
        self._dt = None
        self._z = None
        self._b = self._a = None

    def _coefficients(self, dt_s: float) -> None:
        w0 = 2.0 * math.pi * min(self.f0_hz * dt_s, 0.45)
        alpha = math.sin(w0) / (2.0 * self.q)
        c = -2.0 * math.cos(w0)
        a0 = 1.0 + alpha
        self._b = (1.0 / a0, c / a0, 1.0 / a0)
        self._a = (c / a0, (1.0 - alpha) / a0)
        self._dt = dt_s

    def reset(self) -> None:
        self._z = None  # the next sample starts in the steady state of a constant input (no transient)

    def hold(self, x) -> None:
        """The steady state of a constant input x, as if it had always been there."""
        b0, b1, b2 = self._b
        a1, a2 = self._a
        self._z = [[(b1 - a1 + b2 - a2) * v, (b2 - a2) * v] for v in x]

    def update(self, x, dt_s: float):
        if self._dt is None or abs(dt_s - self._dt) > 1e-3 * self._dt:
            self._coefficients(dt_s)  # a live link's intervals jitter by a few µs: follow changes over 0.1 %
        b0, b1, b2 = self._b
        a1, a2 = self._a
        zs = self._z
        if zs is None:
            zs = self._z = [[(b1 - a1 + b2 - a2) * v, (b2 - a2) * v] for v in x]
        out = []
        for v, z in zip(x, zs):
            y = b0 * v + z[0]
            z[0] = b1 * v - a1 * y + z[1]
            z[1] = b2 * v - a2 * y
            out.append(y)
        return out


class TremorFilter:
    NAME = "tremor"
    PARAMS = {
        "notch_hz": Param(10.0, "Hz", 1.0, 100.0, "centre of the tremor band-stop (physiological tremor: 8–12 Hz)"),
        "notch_q": Param(0.7, "", 0.1, 20.0, "quality factor of each notch (lower = wider band, more delay)"),
        "notch2_hz": Param(0.0, "Hz", 0.0, 100.0, "a second notch (e.g. at the band's other half); 0 = one notch"),
        "pass_dps": Param(8.0, "°/s", 0.0, 10000.0, "intended speed from which motion passes unfiltered (filtered "
                          "fully below half of it); 0 = always filtered"),
        "speed_tau_s": Param(0.05, "s", 0.0, 2.0, "time constant of the intended-speed estimate"),
        "min_cutoff_hz": Param(0.5, "Hz", 0.01, 1000.0, "cutoff of the rest low-pass when still"),
        "beta": Param(48.0, "Hz per °/s", 0.0, 1000.0, "how fast the rest low-pass opens with the intended speed"),
    }
    GRID = {"notch_q": [0.5, 0.6, 0.7], "beta": [12.0, 24.0, 48.0], "min_cutoff_hz": [0.5],
            "pass_dps": [8.0, 15.0, 30.0]}

    def __init__(self, *args, **kwargs):
        p = resolve(self.PARAMS, args, kwargs)
        self.notch_hz, self.notch_q, self.notch2_hz = p["notch_hz"], p["notch_q"], p["notch2_hz"]
        self.pass_dps, self.speed_tau_s = p["pass_dps"], p["speed_tau_s"]
        self.min_cutoff_hz, self.beta = p["min_cutoff_hz"], p["beta"]
        self._notches = [_Notch(self.notch_hz, self.notch_q)]
        if self.notch2_hz > 0:
            self._notches.append(_Notch(self.notch2_hz, self.notch_q))
        self.reset()

    def reset(self) -> None:
        for n in self._notches:
            n.reset()
        self._last = None
        self._v = None
        self._z = None
        self.speed = 0.0

    def update(self, x, dt_s: float):
        if len(x) == 2 and len(self._notches) == 1:
            return self._update2(x, dt_s)
        x = [float(v) for v in x]
        if dt_s <= 0:
            dt_s = 0.005
        y = x
        for n in self._notches:
            y = n.update(y, dt_s)
        last = self._last
        if last is None:
            self._v = [0.0] * len(y)
            self._z = list(y)
        else:
            k = dt_s / (self.speed_tau_s + dt_s)
            v = self._v
            s2 = 0
            for i in range(len(y)):
                vi = v[i] + k * ((y[i] - last[i]) / dt_s - v[i])
                v[i] = vi
                s2 += vi * vi
            speed = self.speed = math.sqrt(s2)
            tau = 1.0 / (_TWO_PI * (self.min_cutoff_hz + self.beta * speed))
            alpha = dt_s / (tau + dt_s)
            z = self._z
            for i in range(len(y)):
                zi = z[i]
                z[i] = zi + alpha * (y[i] - zi)
        self._last = y
        z = self._z
        pass_dps = self.pass_dps
        if pass_dps > 0:
            half = 0.5 * pass_dps
            a = (self.speed - half) / half
            if a >= 1.0:
                for n in self._notches:
                    n.hold(x)
                self._z = list(x)
                self._last = list(x)
                return tuple(x)
            if a > 0.0:
                return tuple([f + a * (r - f) for f, r in zip(z, x)])
        return tuple(z)

    def _update2(self, x, dt_s: float):
        """:meth:`update` for a 2-vector (the pointer's angles) and one notch, written out: the same operations
        in the same order (the same bits), as the pointer runs it at every sample."""
        x0 = float(x[0])
        x1 = float(x[1])
        if dt_s <= 0:
            dt_s = 0.005
        n = self._notches[0]
        if n._dt is None or abs(dt_s - n._dt) > 1e-3 * n._dt:
            n._coefficients(dt_s)
        b0, b1, b2 = n._b
        a1, a2 = n._a
        zs = n._z
        if zs is None:
            zs = n._z = [[(b1 - a1 + b2 - a2) * v, (b2 - a2) * v] for v in (x0, x1)]
        z0, z1 = zs
        y0 = b0 * x0 + z0[0]
        z0[0] = b1 * x0 - a1 * y0 + z0[1]
        z0[1] = b2 * x0 - a2 * y0
        y1 = b0 * x1 + z1[0]
        z1[0] = b1 * x1 - a1 * y1 + z1[1]
        z1[1] = b2 * x1 - a2 * y1
        last = self._last
        if last is None:
            self._v = [0.0, 0.0]
            z = self._z = [y0, y1]
        else:
            k = dt_s / (self.speed_tau_s + dt_s)
            v = self._v
            v0 = v[0] + k * ((y0 - last[0]) / dt_s - v[0])
            v1 = v[1] + k * ((y1 - last[1]) / dt_s - v[1])
            v[0] = v0
            v[1] = v1
            speed = self.speed = math.sqrt(v0 * v0 + v1 * v1)
            tau = 1.0 / (_TWO_PI * (self.min_cutoff_hz + self.beta * speed))
            alpha = dt_s / (tau + dt_s)
            z = self._z
            zi = z[0]
            z[0] = zi + alpha * (y0 - zi)
            zi = z[1]
            z[1] = zi + alpha * (y1 - zi)
        self._last = [y0, y1]
        pass_dps = self.pass_dps
        if pass_dps > 0:
            half = 0.5 * pass_dps
            a = (self.speed - half) / half
            if a >= 1.0:
                n.hold((x0, x1))
                self._z = [x0, x1]
                self._last = [x0, x1]
                return (x0, x1)
            if a > 0.0:
                f = z[0]
                g = z[1]
                return (f + a * (x0 - f), g + a * (x1 - g))
        return (z[0], z[1])
