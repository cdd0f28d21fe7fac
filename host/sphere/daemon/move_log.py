"""Each pointer move's two times, to split the host's part of the latency (``sphere-mouse --move-log FILE``).

A line per move: when the read that brought the move's sample returned (the source's ``arrival_ns``) and when
the backend's move call returned, in ns of CLOCK_MONOTONIC (Python's ``perf_counter_ns`` on Linux: the clock
the virtual board's ``--host-log`` and ``sphere bench latency``'s pointer watch keep), separated by a space.
The bench joins them with the pty write before and the X server's report after, so the host stage splits into
the wake-up to the read, the daemon's own work and call, and the display server's part.

The times are kept in memory and written between batches, a thousand moves at a time (never on the path from
the read to the move), and the rest when the daemon stops.
"""

from __future__ import annotations

import array
import time

from sphere.errors import SphereError

#: moves kept before they are written
FLUSH_EVERY = 1000


class MoveLogError(SphereError):
    """The move log's file cannot be written."""


class MoveLog:
    def __init__(self, path: str):
        try:
            self._file = open(path, "w", encoding="ascii")
        except OSError as e:
            raise MoveLogError(f"--move-log {path}: cannot write it ({e.strerror}); give a path in a folder you "
                               "can write to") from None
        self.path = path
        self._times = array.array("q")
        self.moves = 0

    def moved(self, read_ns: int) -> None:
        """A move whose sample came with the read that returned at ``read_ns``; its call has just returned."""
        self._times.append(read_ns)
        self._times.append(time.perf_counter_ns())
        self.moves += 1

    def step(self) -> None:
        """Between batches: write what was kept, once there is enough of it."""
        if len(self._times) >= 2 * FLUSH_EVERY:
            self.flush()

    def flush(self) -> None:
        t = self._times
        self._file.write("".join(f"{t[i]} {t[i + 1]}\n" for i in range(0, len(t), 2)))
        self._file.flush()
        del t[:]

    def close(self) -> None:
        if self._file.closed:
            return
        self.flush()
        self._file.close()


def read_move_log(path) -> list[tuple[int, int]]:
    """(read ns, moved ns) per move, in order; a line cut short by a daemon that was killed is left out."""
    out = []
    with open(path, encoding="ascii") as f:
        for line in f:
            parts = line.split()
            if len(parts) == 2 and line.endswith("\n"):
                out.append((int(parts[0]), int(parts[1])))
    return out
