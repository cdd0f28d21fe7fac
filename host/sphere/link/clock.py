"""The sphere's clock on the host's clock, from ECHO round trips (protocol/spec.md §5.4), and each sample's age.

    clock = DeviceClock()
    clock.echo(lambda: link.send(Echo()), time.monotonic)                # every 0.5 s
    clock.reply(reply, time.monotonic())                               # its REPLY (data: device_t_us)
    clock.host_s(dp.t_us)                                              # a sample's device time, in host seconds
    ages.add(arrival_s - clock.host_s(dp.t_us), arrival_s)             # its age on arrival

A round trip gives the host's times ``h0`` (ECHO written) and ``h1`` (REPLY read) around the device's
``device_t_us`` (the ECHO's frame complete). Each leg is its bytes on the wire plus waits that only lengthen it
(the USB adapter's latency timer, the device's loop busy with a sample, a reply queued behind frames, the
host's scheduler), so each trip bounds the device time in host time: at least ``h0 + up``, at most
``h1 − down`` (``up``, ``down``: the two frames' wire times at the link's baud rate). Over the last
:data:`WINDOW` trips (16 s at one every 0.5 s) the clock is the straight line (offset and rate: the clocks'
drift — a ceramic resonator's 0.5 % is 5 ms a second — is followed)
with the most room between all the bounds, placed in the middle of it; :attr:`DeviceClock.uncertainty_s` is
half that room, the most the offset can be off. The tightest bounds come from different trips: one that did
not wait on the way up, another that did not wait on the way back.

Why not the samples' own arrival times (the lower envelope of arrival − t_us)? That gives the offset plus
the device's own sample-to-send time, which depends on what else was queued before the frame: the age would
be the age over the best case, not the age.
"""

from __future__ import annotations

import collections
import statistics

WINDOW = 32
#: trips closer together than this leave the rate open: rate 1 until then
MIN_SPAN_S = 0.2
#: the largest rate difference of the two clocks looked for: a ceramic resonator's ±0.5 % with margin
MAX_DRIFT = 0.02
#: on the wire (COBS and delimiter included): ECHO = 4-byte payload, its REPLY = 11-byte payload
ECHO_WIRE_BYTES = 6
REPLY_WIRE_BYTES = 13
U32 = 1 << 32


class DeviceClock:
    def __init__(self, baud: int = 115200):
        self.baud = baud
        self._sent: dict[int, float] = {}
        self._trips: collections.deque = collections.deque(maxlen=WINDOW)  # (rtt_s, device_s, host_s, wait_s)
        self._last_us: int | None = None  # the latest unwrapped device time seen (sample or echo)
        self._fit: tuple[float, float, float] | None = None  # host = a + b * (device - d0)
        self.uncertainty_s: float | None = None

    # -- the round trips --
    def echo(self, send, now) -> int:
        """Send an ECHO (``send()`` writes it and returns its sequence number) and note when: the host's time is
        read *before* the write. Read after it, a writer that was preempted between the write and the clock read
        would give a lower bound (h0 + up) later than the device's true time, and since the fit keeps the
        tightest bound of 32 trips, that one trip would shift every age by the preemption (a loaded machine
        showed ages 1-2 ms below the truth)."""
        h0 = now()
        seq = send()
        self.sent(seq, h0)
        return seq

    def sent(self, seq: int, host_s: float) -> None:
        self._sent[seq] = host_s
        if len(self._sent) > 16:  # replies that never came
            for k in sorted(self._sent, key=self._sent.get)[:-16]:
                del self._sent[k]

    def reply(self, reply, host_s: float) -> bool:
        """Take a REPLY to ECHO (data = device_t_us); False when it is not one we are waiting for."""
        h0 = self._sent.pop(reply.cmd_seq, None)
        if h0 is None or not reply.ok or len(reply.data) != 4:
            return False
        device_s = self._unwrap(int.from_bytes(reply.data, "little")) / 1e6
        up, down = ECHO_WIRE_BYTES * 10 / self.baud, REPLY_WIRE_BYTES * 10 / self.baud
        rtt = host_s - h0
        wait = max(0.0, rtt - up - down)
        self._trips.append((rtt, device_s, h0 + up + wait / 2, wait, h0 + up, host_s - down))
        self._refit()
        return True

    def restart(self, baud: int | None = None) -> None:
        """A new connection, a reset of the device (HELLO) or another baud rate: the old trips no longer hold."""
        if baud is not None:
            self.baud = baud
        self._sent.clear()
        self._trips.clear()
        self._last_us = None
        self._fit = None
        self.uncertainty_s = None

    def _refit(self) -> None:
        # Every trip bounds the device's time in host time: at least ``up`` after h0, at least ``down`` before h1.
        # A line host = a + b·(device − d0) must pass between all the bounds; for a rate b the room left is
        # min(high_i − b·x_i) − max(low_i − b·x_i), a concave function of b: the rate with the most room (found by
        # ternary search within ±MAX_DRIFT) is the one the bounds pin down best, and the offset is the middle of
        # that room. The tightest lower and upper bounds may come from different trips (one that did not wait
        # going up, another that did not wait coming back), which a midpoint of one trip cannot use.
        trips = list(self._trips)
        d0 = trips[-1][1]
        pts = [(t[1] - d0, t[4], t[5]) for t in trips]

        def room(b):
            return min(hi - b * x for x, _, hi in pts) - max(lo - b * x for x, lo, _ in pts)

        xs = [x for x, _, _ in pts]
        b = 1.0
        if max(xs) - min(xs) >= MIN_SPAN_S:
            lo_b, hi_b = 1.0 - MAX_DRIFT, 1.0 + MAX_DRIFT
            for _ in range(60):
                m1, m2 = lo_b + (hi_b - lo_b) / 3, hi_b - (hi_b - lo_b) / 3
                if room(m1) < room(m2):
                    lo_b = m1
                else:
                    hi_b = m2
            b = (lo_b + hi_b) / 2
        low = max(lo - b * x for x, lo, _ in pts)
        high = min(hi - b * x for x, _, hi in pts)
        if low > high:  # no line fits every bound (the device's clock jumped): keep the latest trip only
            last = trips[-1]
            self._trips.clear()
            self._trips.append(last)
            low, high = last[4], last[5]
            b = 1.0
        self._fit = ((low + high) / 2, b, d0)
        self.uncertainty_s = (high - low) / 2

    # -- device time --
    def _unwrap(self, t_us: int) -> int:
        """A raw u32 device time near the latest one seen, unwrapped like the packet stream's."""
        if self._last_us is None:
            self._last_us = t_us
            return t_us
        delta = (t_us - self._last_us) % U32
        if delta >= U32 // 2:
            delta -= U32
        self._last_us += delta
        return self._last_us

    def note_sample(self, t_us: int) -> None:
        """The unwrapped time of a sample (``DecodedPacket.t_us``): the reference for unwrapping ECHO's u32."""
        self._last_us = t_us

    @property
    def ready(self) -> bool:
        return self._fit is not None

    def host_s(self, t_us: int) -> float | None:
        """Host time (the clock the round trips were timed with) of device time ``t_us`` (unwrapped µs)."""
        if self._fit is None:
            return None
        a, b, d0 = self._fit
        return a + b * (t_us / 1e6 - d0)


#: after an age that grew came back, a new "growing" is said only this much later (a link that comes and goes
#: is one line a minute, not one a second)
QUIET_S = 60.0


class SampleAges:
    """Ages of recent samples (median, p95) and whether they grow: a link whose age climbs (Bluetooth congestion,
    a stalled adapter) is said once, and once more when it is back."""

    #: a one-second median this far above the best one-second median so far, twice in a row, is "growing"
    GROWING_S = 0.020

    #: the run's ages are counted in steps of this many seconds (bounded memory however long the daemon runs)
    RUN_STEP_S = 1e-4

    def __init__(self, keep_s: float = 2.0):
        self.keep_s = keep_s
        self._ages: collections.deque = collections.deque()  # (host_s, age_s)
        self._run: collections.Counter = collections.Counter()  # the whole run: age in RUN_STEP_S steps -> samples
        self.run_samples = 0
        self.growing_spells = 0  # how often the age started growing over the run
        self._second: list[float] = []
        self._second_start: float | None = None
        self.best_median_s: float | None = None
        self._high_seconds = 0
        self.growing = False
        self._ended_at = -1e18

    def add(self, age_s: float, host_s: float) -> str | None:
        """Note one sample's age; returns a line to log when the age starts or stops growing, else None."""
        self._ages.append((host_s, age_s))
        self._run[round(age_s / self.RUN_STEP_S)] += 1
        self.run_samples += 1
        while self._ages and host_s - self._ages[0][0] > self.keep_s:
            self._ages.popleft()
        if self._second_start is None:
            self._second_start = host_s
        self._second.append(age_s)
        if host_s - self._second_start < 1.0:
            return None
        med = statistics.median(self._second)
        self._second, self._second_start = [], host_s
        if self.best_median_s is None or med < self.best_median_s:
            self.best_median_s = med
        # no sample arrives before it was taken: a median below zero is the clock's fit off (a device clock that
        # jumped ahead, as a starved simulated board catching up with the wall clock does), not a faster link, so
        # growth is judged from zero up
        high = med > max(self.best_median_s, 0.0) + self.GROWING_S
        self._high_seconds = self._high_seconds + 1 if high else 0
        if self._high_seconds >= 2 and not self.growing and host_s - self._ended_at >= QUIET_S:
            self.growing = True
            self.growing_spells += 1
            return (f"the sphere's samples arrive {med * 1e3:.0f} ms old (was {max(self.best_median_s, 0.0) * 1e3:.1f} ms): "
                    "the link is congested (Bluetooth?) or the adapter stalls")
        if self.growing and not high:
            self.growing = False
            self._ended_at = host_s
            return f"the sphere's samples arrive {med * 1e3:.1f} ms old again"
        return None

    def percentiles_ms(self) -> tuple[float, float] | None:
        """(median, p95) of the last ``keep_s`` seconds, in ms; None before any."""
        if not self._ages:
            return None
        a = sorted(age for _, age in self._ages)
        return a[len(a) // 2] * 1e3, a[min(len(a) - 1, int(0.95 * len(a)))] * 1e3

    def run_percentiles_ms(self, ps=(50, 95)) -> tuple[float, ...] | None:
        """The given percentiles (nearest rank, 100 = the largest) of every age noted since this object was made,
        a reconnect's :meth:`clear` included, in ms (to 0.1 ms); None before any."""
        if not self.run_samples:
            return None
        steps = sorted(self._run.items())
        out = []
        for p in ps:
            rank, seen = min(self.run_samples - 1, int(p / 100 * self.run_samples)), 0
            for step, n in steps:
                seen += n
                if seen > rank:
                    out.append(step * self.RUN_STEP_S * 1e3)
                    break
        return tuple(out)

    def clear(self) -> None:
        """A new link (a reconnect): the recent window and the growth test start again; the run's ages stay."""
        self._ages.clear()
        self._second, self._second_start = [], None
        self.best_median_s = None
        self._high_seconds = 0
        self.growing = False
        self._ended_at = -1e18
