"""The garbage collector off the pointer's path (sphere.daemon.collector): while sphere-mouse's loop runs, no
collection starts inside a packet's handling; they run between batches, as often as CPython's thresholds say."""

from __future__ import annotations

import gc

from sphere.daemon.app import SphereMouse
from sphere.daemon.backends.memory import RecordingBackend
from sphere.daemon.collector import BetweenBatches
from sphere.daemon.config import Config
from sphere.daemon.sources.scripted import ScriptedSource
from sphere.daemon.scripted_sphere import DEMO_SCRIPT


class _Cycle:
    def __init__(self):
        self.me = self


def test_the_daemon_collects_between_batches_only_and_gives_the_collector_back():
    cfg = Config().with_overrides({"outputs.page": {"enabled": False}}, "test")
    source = ScriptedSource(DEMO_SCRIPT, loop=False, speed=0)
    daemon = SphereMouse(cfg, source, RecordingBackend(), log=lambda m: None)
    inside = {"now": False, "during": 0, "between": 0}
    handle = daemon.handle

    def handled(dp):
        inside["now"] = True
        try:
            for _ in range(3):
                _Cycle()  # garbage only a collection frees, so that collections come due during the run
            handle(dp)
        finally:
            inside["now"] = False

    def seen(phase, info):
        if phase == "start":
            inside["during" if inside["now"] else "between"] += 1

    daemon.handle = handled
    assert gc.isenabled()
    gc.callbacks.append(seen)
    try:
        assert daemon.run() == 0
    finally:
        gc.callbacks.remove(seen)
    assert daemon.moves > 0
    assert inside["during"] == 0, inside
    # the start collects once (before freezing what start-up left alive), then the loop between batches
    assert inside["between"] >= 3 and 1 + sum(daemon.collector.collections) == inside["between"], inside
    assert gc.isenabled() and gc.get_freeze_count() == 0  # the process has its automatic collection back


def test_a_collection_is_due_by_cpythons_thresholds_and_frees_cycles():
    c = BetweenBatches()
    c.start()
    try:
        assert not gc.isenabled() and gc.get_freeze_count() > 0
        threshold = gc.get_threshold()[0]
        before = list(c.collections)
        c.step()  # nothing allocated since the start: not due
        assert c.collections == before
        cycles = [_Cycle() for _ in range(threshold + 10)]
        del cycles
        c.step()
        assert sum(c.collections) == sum(before) + 1 and gc.get_count()[0] < threshold
    finally:
        c.stop()
    assert gc.isenabled() and gc.get_freeze_count() == 0


def test_a_program_that_switched_the_collector_off_keeps_it_off():
    gc.disable()
    try:
        c = BetweenBatches()
        c.start()
        assert not c.active and gc.get_freeze_count() == 0
        c.step()
        c.stop()
        assert not gc.isenabled()
    finally:
        gc.enable()
