"""The one connection loop every source shares: connect, read, decode, notice a lost link, look again.

A source is iterated for *batches*: each is a list of :class:`sphere.protocol.DecodedPacket` (device
time unwrapped, duplicates dropped), possibly empty (a tick while nothing arrives, so the daemon keeps
time). ``source.arrival_ns`` is ``time.perf_counter_ns()`` taken right after the batch's bytes were
read (where the benchmark's latency starts), ``source.stats`` the frame decoder's counters,
``source.state`` a short text for the status line, and ``source.generation`` grows by one at every new
connection (the daemon then restarts its time base).

A subclass says how to reach its device and nothing else:

- :meth:`Source._connect` — find and open the device; returns the first packets (``[]`` is fine) or
  None when it is not there (the loop tries again every ``reconnect_interval_s``);
- :meth:`Source._read` — the bytes that arrived (``b""`` when none within a short wait); raise
  :class:`LinkLost` (or OSError / serial.SerialException) when the device went away;
- :meth:`Source._disconnect` — close what ``_connect`` opened;
- optionally :meth:`Source._batch` (a source that is not a byte stream, e.g. a paced replay),
  :meth:`Source._after_batch` (what it notes of a batch once the daemon has handled it, off the pointer's path) and
  :meth:`Source._over` (a finite source: the iteration ends instead of looking again).
"""

from __future__ import annotations

import logging
import time
from typing import Iterator

import serial

from sphere.daemon.sources import PARAMS as SOURCE_PARAMS
from sphere.errors import LinkLost, SphereError
from sphere.protocol import PROTOCOL_VERSION, DecodedPacket, Hello, PacketStream
from sphere.protocol.packets import SUPPORTED_VERSIONS

log = logging.getLogger("sphere.daemon.source")


class SourceError(SphereError):
    """A source that cannot go on; the message says what to do. The daemon stops with it."""


class SourceFailed(SourceError):
    """The device failed during the run and will not come back (the virtual board killed): the daemon stops with
    it, exit status 1."""


class SourceEnded(Exception):
    """A finite source (a capture, the simulated board's run) has nothing more."""


#: pause between attempts to find the sphere again, unless ``[source] reconnect_interval_s`` says otherwise
RECONNECT_INTERVAL_S = SOURCE_PARAMS["reconnect_interval_s"].default


def reconnect_interval_s(cfg) -> float:
    """``[source] reconnect_interval_s`` of a loaded config (the sources' default without one)."""
    return cfg.source.reconnect_interval_s if cfg is not None else RECONNECT_INTERVAL_S


def version_problem(hello: Hello) -> str | None:
    """None if we speak the device's protocol, else what to update (spec §4.1, version handshake)."""
    v = hello.protocol_version
    if v in SUPPORTED_VERSIONS:
        return None
    side = "the host software (pip install -U marg-sphere)" if v > PROTOCOL_VERSION else "the sphere's firmware"
    spoken = " and ".join(str(x) for x in SUPPORTED_VERSIONS)
    return (f"the sphere speaks protocol version {v}, this sphere-mouse speaks version {spoken}: "
            f"update {side}")


class Source:
    """Base of every source: the connection loop, the packet stream and the counters."""

    #: the name in ``[source] kind`` and in the registry (sphere.daemon.sources.REGISTRY)
    NAME = ""
    #: the settings of ``[source.NAME]`` (sphere.settings.Param)
    PARAMS: dict = {}
    #: its batches come at a device's pace (the loop waits for them): the daemon's loop then asks for a higher
    #: scheduling priority (sphere.daemon.priority); never for a replay, which may run as fast as it can
    DEVICE_PACED = False

    def __init__(self, reconnect_interval_s: float = RECONNECT_INTERVAL_S, link_timeout_s: float = 0.0, log=None):
        self.stream = PacketStream("device")
        self.reconnect_interval_s = reconnect_interval_s
        self.link_timeout_s = link_timeout_s  # 0 = silence is not a lost link
        self._log_fn = log  # a callable taking one line (tests), else the "sphere.daemon.source" logger
        self.arrival_ns = 0
        self.generation = 0
        self.connects = 0
        self.losses = 0
        self.connected = False
        self.state = "starting"
        self._stop = False
        self._iterating = False
        self._last_byte = 0.0

    # -- what the daemon reads --
    @property
    def host_time_s(self) -> float:
        """When the current batch arrived, on the host clock (s, ``time.perf_counter``; a recorded session's
        replay: the recorded time, on the session's clock)."""
        return self.arrival_ns * 1e-9

    @property
    def stats(self):
        return self.stream.stats

    @property
    def hello(self) -> Hello | None:
        return self.stream.hello

    def log(self, msg: str, level: int = logging.INFO) -> None:
        """One line: to the ``log`` callable given, or the logger; a DEBUG line (what `sphere-mouse -v` adds)
        always goes to the logger, which drops it unless -v."""
        if self._log_fn is not None and level >= logging.INFO:
            self._log_fn(msg)
        else:
            log.log(level, msg)

    @classmethod
    def from_settings(cls, settings, log=None, cfg=None):
        """The source from its ``[source.NAME]`` settings (its ``PARAMS``); ``cfg`` is the whole config, for
        the ``[source]`` keys every source shares (``reconnect_interval_s``). Each source defines this."""
        raise NotImplementedError

    # -- what a subclass provides --
    def _connect(self) -> list[DecodedPacket] | None:
        raise NotImplementedError

    def _read(self) -> bytes:
        raise NotImplementedError

    def _disconnect(self) -> None:
        pass

    def _over(self) -> bool:
        """True when the source has ended for good (not lost: finished)."""
        return False

    def _after_batch(self, batch: list[DecodedPacket]) -> None:
        """What a source notes of a batch once the daemon has handled it (its pointer move is out), before the next
        read: bookkeeping that need not wait in front of the move. Nothing here."""

    def _batch(self) -> list[DecodedPacket]:
        data = self._read()
        if data:
            self.arrival_ns = time.perf_counter_ns()
            self._last_byte = time.monotonic()
            return self.stream.feed(data)
        if self.link_timeout_s and time.monotonic() - self._last_byte > self.link_timeout_s:
            raise LinkLost(f"no data for {self.link_timeout_s:g} s")
        return []

    # -- the loop --
    def __iter__(self) -> Iterator[list[DecodedPacket]]:
        self._iterating = True
        try:
            yield from self._loop()
        finally:
            self._iterating = False
            self._close()

    def _loop(self) -> Iterator[list[DecodedPacket]]:
        last_try = -1e18
        while not self._stop:
            if not self.connected:
                if self._over():
                    return
                now = time.monotonic()
                if now - last_try < self.reconnect_interval_s:
                    time.sleep(min(0.05, self.reconnect_interval_s))
                    yield []
                    continue
                last_try = now
                try:
                    packets = self._connect()
                except LinkLost as e:  # gone while being set up (unplugged during the hello or the baud switch)
                    self.connected = True  # half set up: _lose closes what _connect opened
                    self._lose(str(e))
                    yield []
                    continue
                if packets is None:
                    yield []
                    continue
                self.connected = True
                self.connects += 1
                self.generation += 1
                self._last_byte = time.monotonic()
                yield packets
                continue
            try:
                batch = self._batch()
            except SourceEnded:
                self._close()
                return
            except (LinkLost, OSError, serial.SerialException) as e:
                self._lose(str(e))
                yield []
                continue
            yield batch
            if batch:
                self._after_batch(batch)

    #: what the log and the status line call the device
    DEVICE = "the sphere"

    def _lose(self, why: str) -> None:
        self._close()
        self.losses += 1
        self.state = f"looking for {self.DEVICE} (link lost)"
        self.log(f"lost {self.DEVICE} ({why}); looking for it again", logging.WARNING)

    def _close(self) -> None:
        if self.connected:
            self.connected = False
            try:
                self._disconnect()
            except Exception:  # closing a device that is already gone
                pass

    def close(self) -> None:
        """Stop: the loop closes the device when it sees this (safe from another thread; the daemon's
        signal handlers only set a flag and the loop calls this)."""
        self._stop = True
        if not self._iterating:
            self._close()
