"""``synthetic:tour``: a sphere that shows everything sphere-mouse does, for the demo.

One round (TOUR_S seconds), repeated until the trace ends:

==========  ================================================================================
 0 – 3 s    still on the desk (the firmware's power-up gyro bias)
 pointer    turn right, back; left, back; up, back; down, back (smooth 20° / 12° wrist turns)
 tap        a single knock on the shell (a click), then a double knock (a double click)
 toss       thrown up and caught: free fall → next mode, **tilt**
 tilt       turned right and held, back; nose down and held, back (the pointer glides while held)
 toss       → **3d**: the 3-D page turns with the sphere
 3-D        slow turns about each axis in turn
 toss       → back to **pointer** for the next round
==========  ================================================================================

The sensor frame is the one sphere-mouse uses: x towards the screen, y to the left, z up. Turning right
is a negative rotation about z, up a negative rotation about y (the nose, x, rises). Taps and tosses are
the same physical events as ``synthetic:taps`` and ``synthetic:toss`` (sphere.sim.trace).
"""

from __future__ import annotations

import numpy as np

from sphere import chips
from sphere import quaternion as quat
from sphere.sim.trace import GRAVITY_UP_M_S2, SYNTH_RATE_HZ, Motion, _from_orientation, _integrate

RIGHT, LEFT = (0.0, 0.0, -1.0), (0.0, 0.0, 1.0)
UP, DOWN = (0.0, -1.0, 0.0), (0.0, 1.0, 0.0)
ROLL_RIGHT, ROLL_LEFT = (1.0, 0.0, 0.0), (-1.0, 0.0, 0.0)

TAP_PEAK_G = 4.0
TAP_WIDTH_S = 0.012
DOUBLE_TAP_GAP_S = 0.15


class _Script:
    """Builds body rates, extra acceleration and free-fall marks segment by segment."""

    def __init__(self, rate_hz: float):
        self.rate_hz = rate_hz
        self.gyr: list[np.ndarray] = []
        self.taps: list[float] = []   # times of knocks (s)
        self.tosses: list[float] = []  # times the flight starts (s)
        self.steps: list[tuple[float, str]] = []  # (time, what the viewer should see)
        self.t = 0.0

    def _n(self, seconds: float) -> int:
        return int(round(seconds * self.rate_hz))

    def note(self, what: str) -> None:
        self.steps.append((self.t, what))

    def still(self, seconds: float) -> None:
        self.gyr.append(np.zeros((self._n(seconds), 3)))
        self.t += self._n(seconds) / self.rate_hz

    def turn(self, axis, degrees: float, seconds: float) -> None:
        """A smooth turn (rate follows a sine bump: starts and stops at rest)."""
        n = self._n(seconds)
        u = (np.arange(n) + 0.5) / n
        rate = np.radians(degrees) / seconds * (1 - np.cos(2 * np.pi * u))  # integrates to `degrees`
        self.gyr.append(rate[:, None] * np.asarray(axis, dtype=float))
        self.t += n / self.rate_hz

    def there_and_back(self, axis, degrees: float, what: str, hold_s: float = 0.6) -> None:
        self.note(what)
        self.turn(axis, degrees, 0.8)
        self.still(hold_s)
        self.turn(axis, -degrees, 0.8)
        self.still(0.8)

    def tap(self) -> None:
        self.taps.append(self.t + 0.2)
        self.still(1.6)

    def double_tap(self) -> None:
        self.taps += [self.t + 0.2, self.t + 0.2 + DOUBLE_TAP_GAP_S]
        self.still(1.8)

    def toss(self, spin_dps: float = 200.0, flight_s: float = 0.4) -> None:
        """A throw (0.1 s at 1.5 g), flight (free fall, spinning a full turn back), a catch, then still."""
        self.still(0.5)
        self.tosses.append(self.t + 0.1)
        self.still(0.1)
        n = self._n(flight_s)
        half = np.radians(spin_dps) * np.ones(n)
        half[n // 2:] *= -1  # spins out and back: lands as it left
        self.gyr.append(half[:, None] * np.array([1.0, 0.0, 0.0]))
        self.t += n / self.rate_hz
        self.still(1.5)


def tour_script(rate_hz: float = SYNTH_RATE_HZ) -> _Script:
    s = _Script(rate_hz)
    s.note("still: the firmware estimates the gyro bias")
    s.still(3.0)
    s.note("pointer mode")
    s.there_and_back(RIGHT, 20.0, "pointer right and back")
    s.there_and_back(LEFT, 20.0, "pointer left and back")
    s.there_and_back(UP, 12.0, "pointer up and back")
    s.there_and_back(DOWN, 12.0, "pointer down and back")
    s.note("tap: a click")
    s.tap()
    s.note("double tap: a double click")
    s.double_tap()
    s.note("toss: tilt mode")
    s.toss()
    s.there_and_back(RIGHT, 15.0, "turned right and held: the pointer glides right", hold_s=1.5)
    s.there_and_back(DOWN, 15.0, "nose down and held: the pointer glides down", hold_s=1.5)
    s.note("toss: 3-D mode (open the page)")
    s.toss()
    for axis, what in ((LEFT, "3-D: turning about the vertical"), (ROLL_RIGHT, "3-D: rolling"),
                       (UP, "3-D: pitching")):
        s.there_and_back(axis, 60.0, what, hold_s=0.5)
    s.note("toss: back to pointer mode")
    s.toss()
    return s


TOUR_S = tour_script(100.0).t


def tour(seconds: float, rate_hz: float = SYNTH_RATE_HZ) -> Motion:
    """The tour, repeated (cut) to ``seconds``."""
    one = tour_script(rate_hz)
    gyr_round = np.vstack(one.gyr)
    n = int(round(seconds * rate_hz))
    rounds = max(1, -(-n // len(gyr_round)))
    gyr = np.tile(gyr_round, (rounds, 1))[:n]
    q = _integrate(gyr, rate_hz)
    t = np.arange(n) / rate_hz
    period = len(gyr_round) / rate_hz
    extra = np.zeros((n, 3))
    free_fall = np.zeros(n, dtype=bool)
    qc = quat.conjugate(q)
    g = chips.STANDARD_GRAVITY_M_S2
    for r in range(rounds):
        base = r * period
        for t0 in one.taps:  # a knock on the shell: a half-sine spike along z (as synthetic:taps)
            sel = (t >= base + t0) & (t < base + t0 + TAP_WIDTH_S)
            extra[sel, 2] += TAP_PEAK_G * g * np.sin(np.pi * (t[sel] - base - t0) / TAP_WIDTH_S)
        for t0 in one.tosses:  # as synthetic:toss: 1.5 g up for 0.1 s, 0 g in flight, 3 g at the catch
            throw = (t >= base + t0 - 0.1) & (t < base + t0)
            flight = (t >= base + t0) & (t < base + t0 + 0.4)
            catch = (t >= base + t0 + 0.4) & (t < base + t0 + 0.45)
            extra[throw] = quat.rotate(qc[throw], np.broadcast_to(0.5 * GRAVITY_UP_M_S2, (throw.sum(), 3)))
            extra[catch] = quat.rotate(qc[catch], np.broadcast_to(2.0 * GRAVITY_UP_M_S2, (catch.sum(), 3)))
            free_fall |= flight
    return _from_orientation(q, gyr, rate_hz, "tour", free_fall=free_fall, extra_acc=extra)


def synthetic(seconds: float, arg: str) -> Motion:
    """The registry's entry (sphere.sim.trace.SYNTHETIC): ``synthetic:tour`` takes no argument."""
    if arg:
        raise ValueError("takes no argument")
    return tour(seconds)
