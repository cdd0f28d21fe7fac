"""The status line: source, link quality (frames/s, CRC errors, lost frames), mode, battery; and the run's
figures ``sphere-mouse --print-stats`` prints when the daemon stops."""

from __future__ import annotations

import sys
import time


def _size(n: int) -> str:
    return f"{n} B" if n < 10_000 else f"{n / 1000:.0f} kB"


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
        """Counters of the link as it is (protocol/spec.md §2.1, §3): every kind of bad chunk (framing, CRC,
        oversize, unknown type, bad length) counts in ``bad``, with the bytes it cost; a reconnect starts the
        sequence count again instead of counting the frames not sent while unplugged as lost."""
        src = daemon.source
        s = src.stats
        bad = f"bad {s.errors}" + (f" ({_size(s.bytes_skipped)} skipped)" if s.bytes_skipped else "")
        parts = [src.state, f"{self.rate_fps:.0f} frames/s", bad, f"gaps {s.seq_gaps} ({s.frames_lost} lost)"]
        duplicates = getattr(s, "duplicates", 0)
        if duplicates:
            parts.append(f"duplicates {duplicates}")
        losses = getattr(src, "losses", 0)
        if losses:
            parts.append(f"reconnects {losses}")
        age = getattr(src, "sample_age_ms", None)
        age = age() if age is not None else None
        if age is not None:
            parts.append(f"age {age[0]:.1f}/{age[1]:.1f} ms" + (" growing" if src.ages.growing else ""))
        missing = getattr(daemon, "sensors_missing", ())
        if missing:
            parts.append(", ".join(missing) + " not answering")
        parts.append(f"mode {daemon.mode}" + (" (paused)" if daemon.paused else ""))
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


def run_stats(daemon, seconds: float) -> str:
    """What ``--print-stats`` prints when the daemon stops: the link's counters over the run, each sample's age on
    arrival (a serial link to a protocol-3 sphere: the device clock from ECHO round trips, sphere.link.clock) and
    what the pointer did."""
    src = daemon.source
    s = src.stats
    rate = f" ({s.frames_ok / seconds:.1f}/s)" if seconds > 0 else ""
    lines = [f"frames {s.frames_ok}{rate} over {seconds:.1f} s, bad {s.errors} ({_size(s.bytes_skipped)} skipped), "
             f"gaps {s.seq_gaps} ({s.frames_lost} lost), duplicates {getattr(s, 'duplicates', 0)}, "
             f"reconnects {getattr(src, 'losses', 0)}"]
    ages = getattr(src, "ages", None)
    run = ages.run_percentiles_ms((50, 95, 99, 100)) if ages is not None else None
    if run is None:
        why = ("this source has no device clock" if ages is None else
               "no device clock yet (a protocol-3 sphere answers ECHO; an older one or a short run gives none)")
        lines.append(f"sample age: not known: {why}")
    else:
        clock = getattr(src, "clock", None)
        unc = getattr(clock, "uncertainty_s", None)
        lines.append(f"sample age on arrival: median {run[0]:.1f} ms, p95 {run[1]:.1f} ms, p99 {run[2]:.1f} ms, "
                     f"max {run[3]:.1f} ms ({ages.run_samples} samples"
                     + (f", device clock ±{unc * 1e3:.2f} ms" if unc is not None else "") + "); "
                     + (f"grew {ages.growing_spells} times" if ages.growing_spells else "never grew"))
    line = f"pointer moves {daemon.moves}, clicks {daemon.clicks}, mode {daemon.mode}"
    collector = getattr(daemon, "collector", None)
    if collector is not None:
        line += (f"; garbage collected {sum(collector.collections)} times, between batches (longest "
                 f"{collector.longest_s * 1e3:.1f} ms)")
    lines.append(line)
    priority = getattr(daemon, "priority", None)
    if priority is not None:
        lines.append(f"scheduling of the port -> pointer loop: {priority.granted}"
                     + (" until the runaway guard put it back (a bug: please report it)" if priority.demoted else ""))
    return "\n".join("sphere-mouse stats: " + line for line in lines)
