"""The latency bench's pointer watch (``sphere.bench._xvfb.PointerEvents``) on a real Xvfb: every move the daemon's
own x11 backend makes is reported once, at the position X gives it, and no later than a reader polling the pointer
as fast as the server answers sees it."""

from __future__ import annotations

import random
import shutil
import threading
import time

import pytest

pytestmark = pytest.mark.skipif(shutil.which("Xvfb") is None, reason="needs Xvfb (apt-get install xvfb)")


def test_each_move_of_the_x11_backend_is_reported_once_where_x_put_it():
    from sphere.bench._xvfb import PointerEvents, Xvfb
    from sphere.daemon.backends.x11 import X11Backend

    with Xvfb() as server:
        watch = PointerEvents(server.display)
        backend = X11Backend(server.display)
        try:
            backend.move_to(500, 400)
            assert watch.wait(2.0)
            assert watch.moves()[-1] == (500, 400)
            rng = random.Random(5)
            steps = [(rng.randint(-9, 9), rng.randint(-9, 9)) for _ in range(200)]
            steps = [s for s in steps if s != (0, 0)]
            x, y, expected = 500, 400, []
            for dx, dy in steps:
                backend.move(dx, dy)
                x, y = x + dx, y + dy
                expected.append((x, y))
                time.sleep(0.001)  # paced as the daemon's moves are (at most one a sample): hundreds sent in one burst
                # can overflow the X server's input event queue on a loaded machine, which then drops moves
            seen = []
            deadline = time.monotonic() + 5.0
            while len(seen) < len(expected) and time.monotonic() < deadline:
                if watch.wait(0.1):
                    seen += watch.moves()
            assert seen == expected  # one report per move, in order, none lost, none merged
            assert not watch.wait(0.2) or watch.moves() == []  # and nothing more
            assert watch.position() == (x, y)
        finally:
            backend.close()
            watch.close()


def test_events_see_a_move_no_later_than_a_reader_polling_the_pointer():
    """The bench's two ways of seeing the pointer side by side on the same moves: what the poller sees, the
    events saw (same positions), and not later at the median (the poll adds its period)."""
    from sphere.bench._xvfb import PointerEvents, PointerReader, Xvfb
    from sphere.daemon.backends.x11 import X11Backend

    with Xvfb() as server:
        watch, reader = PointerEvents(server.display), PointerReader(server.display)
        backend = X11Backend(server.display)
        backend.move_to(300, 300)
        time.sleep(0.1)
        watch.moves()
        stop = threading.Event()
        by_event, by_poll = {}, {}

        def listen():
            while not stop.is_set():
                if watch.wait(0.05):
                    now = time.monotonic_ns()
                    for p in watch.moves():
                        by_event.setdefault(p, now)

        def poll():
            last = reader.position()
            while not stop.is_set():
                p = reader.position()
                now = time.monotonic_ns()
                if p != last:
                    by_poll.setdefault(p, now)
                    last = p
                time.sleep(0.0002)

        threads = [threading.Thread(target=listen), threading.Thread(target=poll)]
        for t in threads:
            t.start()
        try:
            for k in range(60):
                backend.move(3, 1)  # each position new: (303 + 3k, 301 + k)
                time.sleep(0.01)
            time.sleep(0.2)
        finally:
            stop.set()
            for t in threads:
                t.join(5)
            backend.close()
            watch.close()
            reader.close()
        moves = [(300 + 3 * k, 300 + k) for k in range(1, 61)]
        assert [p for p in moves if p in by_event] == moves
        polled = [p for p in moves if p in by_poll]
        assert len(polled) >= 50  # 10 ms apart: the poller sees nearly all of them
        leads = sorted(by_poll[p] - by_event[p] for p in polled)
        assert leads[len(leads) // 2] >= 0, leads  # the events' median time is no later than the poll's
