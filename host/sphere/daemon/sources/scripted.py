"""The built-in scripted sphere (sphere.daemon.scripted_sphere), paced in real time, looping."""

from __future__ import annotations

import time

from sphere.daemon import scripted_sphere
from sphere.daemon.sources.base import Source, SourceEnded
from sphere.settings import Param


class ScriptedSource(Source):
    """Frames of :data:`sphere.daemon.scripted_sphere.DEMO_SCRIPT` (or ``script``), as a sphere would send them."""

    NAME = "scripted"
    PARAMS = {"speed": Param(1.0, doc="how fast the script plays: 1 = real time", lo=0.01, hi=1000.0)}

    def __init__(self, script=None, speed: float = 1.0, loop: bool = True):
        super().__init__(reconnect_interval_s=0.0)
        self.script = script or scripted_sphere.DEMO_SCRIPT
        self.speed = speed
        self.loop = loop
        self.state = "scripted sphere (built in)"
        self._done = False
        self._steps = None

    @classmethod
    def from_settings(cls, s, log=None, cfg=None):
        return cls(speed=s.speed)

    def _over(self) -> bool:
        return self._done

    def _connect(self):
        self._sphere = scripted_sphere.ScriptedSphere()
        self._t0, hello = self._sphere.hello()
        self._start = time.perf_counter()
        self._steps = iter(self._sphere.iter_steps(self.script))
        self.arrival_ns = time.perf_counter_ns()
        return self.stream.feed(hello)

    def _batch(self):
        try:
            sample = next(self._steps)
        except StopIteration:
            if not self.loop:
                self._done = True
                raise SourceEnded() from None
            self._steps = iter(self._sphere.iter_steps(self.script))
            return []
        t_us = sample[0][0]
        if self.speed > 0:
            wait = self._start + (t_us - self._t0) * 1e-6 / self.speed - time.perf_counter()
            if wait > 0:
                time.sleep(min(wait, 0.5))
        self.arrival_ns = time.perf_counter_ns()
        return self.stream.feed(b"".join(f for _, f in sample))
