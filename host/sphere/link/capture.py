"""Serial captures: the raw byte stream exactly as it came off the port.

`cat /dev/ttyUSB0 > file` makes a valid capture. A recorder may add a sidecar ``FILE.rx.csv`` with
one line per received chunk, ``byte_offset,host_time_s``: where the chunk starts in the capture and
when the host received it (Unix time), for latency and timing studies.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import BinaryIO, Iterator

from sphere.errors import SphereError
from sphere.paths import resolve_capture
from sphere.protocol.decoder import DecoderStats
from sphere.protocol.stream import DecodedPacket, PacketStream  # noqa: F401  (DecodedPacket: re-exported)

SIDECAR_SUFFIX = ".rx.csv"
READ_CHUNK = 64 * 1024


class CaptureError(SphereError):
    """A capture that cannot be used, with what to do about it."""


def sidecar_path(path: Path | str) -> Path:
    path = Path(path)
    return path.with_name(path.name + SIDECAR_SUFFIX)


class CaptureFile:
    """A capture on disk, read as packets."""

    def __init__(self, path: Path | str):
        try:
            self.path = resolve_capture(path)  # a path, or example:NAME for a capture shipped with the package
        except FileNotFoundError as e:
            raise CaptureError(str(e)) from None
        if not self.path.exists():
            raise CaptureError(f"{self.path}: no such capture file (record one with `sphere capture --port PORT --out FILE`)")
        if self.path.is_dir():
            raise CaptureError(f"{self.path} is a folder, not a capture file")
        if self.path.is_char_device() or self.path.is_block_device():
            raise CaptureError(f"{self.path} is a device, not a capture file: record it with `sphere capture --port "
                               f"{self.path} --out FILE`")
        self.stream = PacketStream("device")
        self.decoder = self.stream.decoder

    @property
    def stats(self) -> DecoderStats:
        return self.stream.stats

    def size(self) -> int:
        return self.path.stat().st_size

    def chunks(self, chunk_size: int = READ_CHUNK) -> Iterator[bytes]:
        """The file's bytes (a FIFO works too); CaptureError when it cannot be read."""
        try:
            with open(self.path, "rb") as f:
                while True:
                    data = f.read(chunk_size)
                    if not data:
                        return
                    yield data
        except OSError as e:
            raise CaptureError(f"{self.path}: cannot read: {e.strerror or e}") from None

    def packets(self, chunk_size: int = READ_CHUNK) -> Iterator[DecodedPacket]:
        """Every packet in the file, in order, with unwrapped device times. Counters in ``stats``."""
        for data in self.chunks(chunk_size):
            yield from self.stream.feed(data)


class CaptureWriter:
    """Appends received bytes to a capture, flushing each chunk to the OS so that a crash, Ctrl-C or
    unplug loses nothing already received; optionally writes the receive-time sidecar."""

    def __init__(self, path: Path | str, with_times: bool = False):
        self.path = Path(path)
        self.bytes_written = 0
        self._times = None
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file: BinaryIO = open(self.path, "wb")
            if with_times:
                self._times = open(sidecar_path(self.path), "w")
                self._times.write("byte_offset,host_time_s\n")
        except OSError as e:
            what = "is a folder" if isinstance(e, IsADirectoryError) else f"cannot be written: {e.strerror or e}"
            raise CaptureError(f"{self.path} {what}; give a file to write the capture to") from None

    def write(self, data: bytes, host_time_s: float | None = None) -> None:
        """Append ``data``; CaptureError (what was kept) when the disk is full or the file cannot be written."""
        if not data:
            return
        try:
            if self._times is not None:
                self._times.write(f"{self.bytes_written},{host_time_s if host_time_s is not None else time.time():.6f}\n")
                self._times.flush()
            self._file.write(data)
            self._file.flush()
        except OSError as e:
            raise CaptureError(f"cannot write {self.path}: {e.strerror or e}; the {self.bytes_written} bytes before "
                               "are kept") from None
        self.bytes_written += len(data)

    def close(self) -> None:
        for f in (self._file, self._times):
            if f is None:
                continue
            try:
                f.close()
            except OSError:  # the last flush failed (a full disk): already reported by write()
                pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
