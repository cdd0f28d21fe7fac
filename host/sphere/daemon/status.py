"""The status line: source, link quality (frames/s, CRC errors, lost frames), mode, battery."""

from __future__ import annotations

import sys
import time


class StatusLine:
    def __init__(self, stream=None, interval_s: float = 1.0, overwrite: bool | None = None, clock=time.monotonic):
        self.stream = stream or sys.stderr
        self.interval_s = interval_s
        self.overwrite = self.stream.isatty() if overwrite is None else overwrite
        self.clock = clock
        self._last_t = None
        self._last_frames = 0
        self.rate_fps = 0.0
        self.last_text = ""

    def text(self, daemon) -> str:
        src = daemon.source
        s = src.stats
        parts = [src.state, f"{self.rate_fps:.0f} frames/s", f"crc errors {s.crc_errors}",
                 f"gaps {s.seq_gaps} ({s.frames_lost} lost)", f"mode {daemon.mode}" + (" (paused)" if daemon.paused else "")]
        if daemon.battery_mv:
            parts.append(f"battery {daemon.battery_mv / 1000:.2f} V")
        return " · ".join(parts)

    def tick(self, daemon, force: bool = False) -> str | None:
        now = self.clock()
        frames = daemon.source.stats.frames_ok
        if self._last_t is None:
            self._last_t, self._last_frames = now, frames
            return None
        if not force and now - self._last_t < self.interval_s:
            return None
        dt = now - self._last_t
        if dt > 0:
            self.rate_fps = (frames - self._last_frames) / dt
        self._last_t, self._last_frames = now, frames
        self.last_text = self.text(daemon)
        try:
            if self.overwrite:
                self.stream.write("\r\x1b[K" + self.last_text)
            else:
                self.stream.write(self.last_text + "\n")
            self.stream.flush()
        except (BrokenPipeError, ValueError):
            pass
        return self.last_text
