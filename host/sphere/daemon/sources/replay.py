"""A capture file (``sphere capture``), paced by its device times divided by ``speed``; or a recorded session
(``sphere capture --camera``, :mod:`sphere.link.session`), paced by its host times, its video played in step."""

from __future__ import annotations

import os
import time

from sphere.daemon.sources.base import Source, SourceEnded, SourceError, version_problem
from sphere.link import session as session_mod
from sphere.link.capture import CaptureError, CaptureFile
from sphere.protocol import Hello
from sphere.settings import Param


class ReplaySource(Source):
    """A capture file, paced by its device times divided by ``speed`` (0 = as fast as possible).
    The iteration ends with the file.

    A session folder is paced by the host times its bytes arrived at; ``host_time_s`` is then the recorded
    time of the current packet (the session's clock), which the camera replay (``session``) follows, so
    frames and samples meet exactly as they did, at any speed."""

    NAME = "replay"
    PARAMS = {
        "file": Param("", doc="capture file to replay (`sphere capture --out`; same as `--replay FILE`)"),
        "speed": Param(1.0, doc="replay speed: 1 = as recorded, 4 = four times faster, 0 = as fast as possible "
                                "(`--speed`)", lo=0.0, hi=1e6),
    }

    def __init__(self, path, speed: float = 1.0, clock=time.perf_counter, sleep=time.sleep):
        super().__init__(reconnect_interval_s=0.0)
        self.session = None
        self._t_host = 0.0
        try:
            if session_mod.is_session(path):
                self.session = session_mod.load(path)
                self.capture = CaptureFile(self.session.serial_path)
            else:
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
    def from_settings(cls, s, log=None, cfg=None):
        if not s.file:
            raise SourceError('[source] kind = "replay" needs a capture file: --replay FILE or [source.replay] file')
        return cls(s.file, s.speed)

    def _over(self) -> bool:
        return self._done

    @property
    def host_time_s(self) -> float:
        return self._t_host if self.session is not None else self.arrival_ns * 1e-9

    def _session_packets(self):
        for data, t in self.session.serial_chunks():
            for dp in self.stream.feed(data):
                yield dp, t

    def _connect(self):
        try:
            if self.session is not None:
                self._packets = self._session_packets()
            else:
                self._packets = ((dp, None) for dp in self.capture.packets())
        except CaptureError as e:
            raise SourceError(str(e)) from None
        self._t0_dev = None
        self._t0_wall = None
        return []

    def _batch(self):
        try:
            dp, t_host = next(self._packets)
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
        # a session is paced by when its bytes arrived, a capture by its device times
        t_rec = t_host if t_host is not None else (None if dp.t_us is None else dp.t_us * 1e-6)
        if t_host is not None:
            self._t_host = t_host
        if self.speed > 0 and t_rec is not None:
            if self._t0_dev is None or t_rec < self._t0_dev:
                self._t0_dev, self._t0_wall = t_rec, self.clock()
            wait = self._t0_wall + (t_rec - self._t0_dev) / self.speed - self.clock()
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
