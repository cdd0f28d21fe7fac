"""Python's cyclic garbage collector kept off the pointer's path.

CPython collects whenever allocations trip a generation's threshold, that is anywhere: in the daemon, about every
hundred frames in the middle of one frame's path from the port to the pointer (decoding, the filters, the move),
0.1–1 ms each on a busy machine, and now and then a full collection that walks every object imported at start-up
(numpy, the filters: ≈10 ms). ``sphere bench latency`` saw one in a hundred pointer moves wait for one.

While the daemon's loop runs, :class:`BetweenBatches` therefore

- freezes what start-up left alive (``gc.freeze()``: the modules, the config, the filters live as long as the
  daemon; no collection walks them again),
- switches the automatic collection off, and
- collects between batches, after the batch's pointer move, the generation CPython's own thresholds would have
  chosen (``gc.get_threshold()``; a program that changed them keeps its choice), so as often as before.

A thread of an output (the 3-D page's server) allocates too; the loop comes round at least every read timeout
(20 ms on a serial port), so its garbage is collected as before. :meth:`stop` gives the process back its automatic
collection (the daemon in a test's thread, ``sphere bench daemon``).
"""

from __future__ import annotations

import gc
import time


class BetweenBatches:
    """Collects when the daemon's loop says it may (:meth:`step`, between batches), nowhere else."""

    def __init__(self):
        self.active = False
        self.collections = [0, 0, 0]  # per generation, while active
        self.longest_s = 0.0  # the longest of them

    def start(self) -> None:
        """Collect once, freeze the survivors, take over from the automatic collection. Nothing is taken over
        when the program has switched the collector off itself."""
        if self.active or not gc.isenabled():
            return
        gc.collect()
        gc.freeze()
        gc.disable()
        self.active = True

    def step(self) -> None:
        """A collection if one is due (the thresholds), of the generation CPython would have collected."""
        if not self.active:
            return
        c0, c1, c2 = gc.get_count()
        t0, t1, t2 = gc.get_threshold()
        if t0 <= 0 or c0 <= t0:  # CPython's own tests: a count above its threshold
            return
        generation = 2 if c2 > t2 else 1 if c1 > t1 else 0
        start = time.perf_counter()
        gc.collect(generation)
        self.longest_s = max(self.longest_s, time.perf_counter() - start)
        self.collections[generation] += 1

    def stop(self) -> None:
        """The automatic collection again (and the frozen objects back among the collected ones)."""
        if not self.active:
            return
        self.active = False
        gc.unfreeze()
        gc.enable()
