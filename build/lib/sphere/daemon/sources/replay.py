"""A capture file (``sphere capture``), paced by its device times divided by ``speed``."""

from __future__ import annotations

import os
import time

from sphere.capture import CaptureError, CaptureFile
from sphere.daemon.sources.base import Source, SourceEnded, SourceError, version_problem
from sphere.protocol import Hello


class ReplaySource(Source):
    """A capture file, paced by its device times divided by ``speed`` (0 = as fast as possible).
    The iteration ends with the file."""

    NAME = "replay"

    def __init__(self, path, speed: float = 1.0, clock=time.perf_counter, sleep=time.sleep):
        super().__init__(reconnect_interval_s=0.0)
        try:
            self.capture = CaptureFile(path)
        except CaptureError as e:
            raise SourceError(str(e)) from None
        if not self.capture.path.is_file():  # a FIFO would block the daemon before it could see a SIGTERM
            raise SourceError(f"{path} is not a regular file: --replay needs a capture file (sphere capture --out)")
        self.stream = self.capture.stream
        self.path = str(path)
        self.speed = float(speed)
        self.clock = clock
        self.sleep = sleep
        self.state = f"replay {os.path.basename(self.path)}" + (f" ×{speed:g}" if speed not in (0, 1) else "")
        self._packets = None
        self._done = False

    @classmethod
    def from_config(cls, cfg, log):
        from sphere.daemon.config import ConfigError

        s = cfg.source
        if not s.replay:
            raise ConfigError("[source] kind = \"replay\" needs a capture file: --replay FILE or [source] replay")
        return cls(s.replay, s.speed)

    def _over(self) -> bool:
        return self._done

    def _connect(self):
        try:
            self._packets = self.capture.packets()
        except CaptureError as e:
            raise SourceError(str(e)) from None
        self._t0_dev = None
        self._t0_wall = None
        return []

    def _batch(self):
        try:
            dp = next(self._packets)
        except StopIteration:
            self._done = True
            self.state = f"replay {os.path.basename(self.path)}: ended"
            stats = self.capture.stats
            if stats.bytes_in == 0:
                raise SourceError(f"{self.path} is empty: nothing to replay (record a capture with `sphere capture`)") from None
            if stats.frames_ok == 0:
                raise SourceError(f"no valid frame in {stats.bytes_in} bytes of {self.path}: this is not a sphere capture, "
                                  "or it was recorded at the wrong baud rate (the sphere sends 115200 8N1)") from None
            raise SourceEnded() from None
        except CaptureError as e:
            raise SourceError(str(e)) from None
        p = dp.packet
        if p.TYPE == Hello.TYPE:
            problem = version_problem(p)
            if problem:
                raise SourceError(f"{self.path}: {problem}")
        if self.speed > 0 and dp.t_us is not None:
            if self._t0_dev is None or dp.t_us < self._t0_dev:
                self._t0_dev, self._t0_wall = dp.t_us, self.clock()
            wait = self._t0_wall + (dp.t_us - self._t0_dev) * 1e-6 / self.speed - self.clock()
            if wait > 0:
                self._sleep(wait)
        self.arrival_ns = time.perf_counter_ns()
        return [dp]

    def _sleep(self, seconds: float) -> None:
        """Sleep in short steps so that a stop (SIGTERM) is seen within 0.1 s even in a long pause."""
        end = self.clock() + seconds
        while not self._stop:
            left = end - self.clock()
            if left <= 0:
                return
            self.sleep(min(left, 0.1))

    def _disconnect(self) -> None:
        self._packets = None
