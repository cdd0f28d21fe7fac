"""Sessions: the sphere's serial bytes and a camera's frames recorded together, on one host clock, so that a
run of the hybrid tracker can be played back exactly (`sphere capture --camera DEV`, `sphere-mouse
--replay SESSION`).

A session is a folder::

    session.json         {"format": "sphere-session", "version": 1, "clock": ..., "serial": "serial.bin",
                          "video": "video.avi", "width": W, "height": H, "fps": F, "started_unix_s": ...}
    serial.bin           the serial bytes exactly as received (a capture: `sphere decode` reads it alone)
    serial.bin.rx.csv    byte_offset,host_time_s — one line per chunk as it was read from the port
    video.avi            the frames as the host decoded them, HuffYUV (lossless: the detector sees the same pixels)
    video.csv            frame,host_time_s — when each frame arrived

Both ``host_time_s`` columns are seconds since the session started on one clock, the host's monotonic
clock (``time.perf_counter``): a chunk's time is when its read returned, a frame's when the camera
delivered it. The camera's exposure is not known to the host; the replay assumes ``[camera] latency_ms``
before the arrival, as the live daemon does.
"""

from __future__ import annotations

import csv
import json
import time
from dataclasses import dataclass
from pathlib import Path

from sphere.link.capture import CaptureError, CaptureWriter, sidecar_path

FORMAT = "sphere-session"
VERSION = 1
META = "session.json"
SERIAL = "serial.bin"
VIDEO = "video.avi"
FRAME_TIMES = "video.csv"
CLOCK = "host monotonic clock (time.perf_counter), seconds since the session started"


class SessionError(CaptureError):
    """A session that cannot be written or read, with what to do about it."""


def is_session(path) -> bool:
    p = Path(path)
    return p.is_dir() and (p / META).is_file()


class SessionWriter:
    """Writes a session folder: ``serial(data)`` from the port's thread, ``frame(image)`` from the camera's,
    each stamped on the same clock when called (or with the time given)."""

    def __init__(self, folder, width: int, height: int, fps: float, clock=time.perf_counter, extra=None):
        import cv2  # optional: OpenCV (the camera extra)

        self.folder = Path(folder)
        self.clock = clock
        if self.folder.exists() and not self.folder.is_dir():
            raise SessionError(f"{self.folder} is a file; a session is a folder: give a new folder's name")
        if self.folder.is_dir() and any(self.folder.iterdir()) and not is_session(self.folder):
            raise SessionError(f"{self.folder} is a folder with other files in it; give a new or empty folder")
        self.folder.mkdir(parents=True, exist_ok=True)
        self.t0 = clock()
        self.frames = 0
        self.serial = CaptureWriter(self.folder / SERIAL, with_times=True)
        self._video = cv2.VideoWriter(str(self.folder / VIDEO), cv2.VideoWriter_fourcc(*"HFYU"), float(fps),
                                      (int(width), int(height)))
        if not self._video.isOpened():
            self.serial.close()
            raise SessionError(f"cannot write {self.folder / VIDEO} (OpenCV without the HuffYUV codec?)")
        self._times = open(self.folder / FRAME_TIMES, "w", newline="")
        self._times.write("frame,host_time_s\n")
        meta = {"format": FORMAT, "version": VERSION, "clock": CLOCK, "serial": SERIAL, "video": VIDEO,
                "frame_times": FRAME_TIMES, "width": int(width), "height": int(height), "fps": float(fps),
                "started_unix_s": time.time(), **(extra or {})}
        (self.folder / META).write_text(json.dumps(meta, indent=2) + "\n")

    @property
    def bytes_written(self) -> int:
        return self.serial.bytes_written

    def now(self) -> float:
        return self.clock() - self.t0

    def write_serial(self, data: bytes, t: float | None = None) -> None:
        self.serial.write(data, self.now() if t is None else t)

    def write_frame(self, image, t: float | None = None) -> None:
        t = self.now() if t is None else t
        self._video.write(image)
        self._times.write(f"{self.frames},{t:.6f}\n")
        self._times.flush()
        self.frames += 1

    def close(self) -> None:
        self.serial.close()
        self._video.release()
        self._times.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


@dataclass
class Session:
    folder: Path
    meta: dict
    chunks: list  # [(byte_offset, host_time_s)]
    frame_times: list  # host_time_s of each frame

    @property
    def serial_path(self) -> Path:
        return self.folder / self.meta.get("serial", SERIAL)

    @property
    def video_path(self) -> Path:
        return self.folder / self.meta.get("video", VIDEO)

    def serial_chunks(self):
        """(bytes, host_time_s) per chunk as it was received."""
        data = self.serial_path.read_bytes()
        offsets = [o for o, _ in self.chunks] + [len(data)]
        for k, (o, t) in enumerate(self.chunks):
            yield data[o:offsets[k + 1]], t


def load(folder) -> Session:
    """A session folder, checked (SessionError says what is wrong and what to do)."""
    folder = Path(folder)
    if not is_session(folder):
        raise SessionError(f"{folder} is not a session folder (no {META}); record one with "
                           f"`sphere capture --port PORT --camera DEV --out FOLDER`")
    try:
        meta = json.loads((folder / META).read_text())
    except (OSError, ValueError) as e:
        raise SessionError(f"{folder / META} cannot be read: {e}") from None
    if meta.get("format") != FORMAT or meta.get("version") != VERSION:
        raise SessionError(f"{folder / META} is not a {FORMAT} version {VERSION} description")
    serial = folder / meta.get("serial", SERIAL)
    chunks = _read_csv(sidecar_path(serial), "byte_offset", int)
    frames = [t for _, t in _read_csv(folder / meta.get("frame_times", FRAME_TIMES), "frame", int)]
    if not serial.is_file():
        raise SessionError(f"{serial} is missing: the session has no serial bytes")
    size = serial.stat().st_size
    if any(o > size for o, _ in chunks) or any(b[0] < a[0] for a, b in zip(chunks, chunks[1:])):
        raise SessionError(f"{sidecar_path(serial)} does not match {serial.name} (offsets past its end or out of order)")
    if not chunks and size:
        chunks = [(0, 0.0)]
    return Session(folder, meta, chunks, frames)


def _read_csv(path: Path, first: str, kind) -> list:
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except OSError as e:
        raise SessionError(f"{path} cannot be read: {e.strerror or e}") from None
    if not rows or rows[0][:1] != [first]:
        raise SessionError(f"{path} is not a session's time file (its header must start with {first!r})")
    out = []
    for n, row in enumerate(rows[1:], 2):
        try:
            out.append((kind(row[0]), float(row[1])))
        except (ValueError, IndexError):
            raise SessionError(f"{path} line {n}: {','.join(row)!r} is not a number and a time") from None
    return out
