"""sphere-mouse --move-log: each pointer move's read and call times, and the latency bench's split of the host stage
with them."""

from __future__ import annotations

import time

import numpy as np
import pytest

from sphere.bench.latency import HOST_SPLIT, Frame, attribute
from sphere.daemon import move_log as M
from sphere.daemon.app import SphereMouse
from sphere.daemon.backends.memory import RecordingBackend
from sphere.daemon.config import Config
from sphere.daemon.sources.replay import ReplaySource
from sphere.errors import SphereError
from sphere.paths import repo_path


def test_the_daemon_logs_every_move_after_the_read_that_brought_it(tmp_path, monkeypatch):
    monkeypatch.setattr(M, "FLUSH_EVERY", 100)
    path = tmp_path / "moves.txt"
    cfg = Config().with_overrides({"outputs.page": {"enabled": False}, "output": {"screen_width_px": 1280}}, "test")
    backend = RecordingBackend(screen_size=None)
    daemon = SphereMouse(cfg, ReplaySource(repo_path("tests", "captures", "sim_07_fast_rotation.bin"), speed=0),
                         backend, log=lambda m: None)
    log = daemon.move_log = M.MoveLog(str(path))
    flushes = []
    flush = log.flush
    log.flush = lambda: (flushes.append(len(log._times) // 2), flush())
    start = time.perf_counter_ns()
    daemon.run()
    got = M.read_move_log(path)
    assert backend.moves > 700
    # written between batches a hundred at a time (here), the rest when the loop ended
    assert flushes[:-1] == [100] * (backend.moves // 100) and flushes[-1] == backend.moves % 100
    assert len(got) == backend.moves == daemon.move_log.moves
    reads, moved = np.array(got).T
    assert (reads >= start).all() and (moved >= reads).all() and (np.diff(moved) > 0).all()
    assert moved[-1] <= time.perf_counter_ns()


def test_a_path_that_cannot_be_written_is_one_clear_error(tmp_path):
    with pytest.raises(M.MoveLogError, match=r"--move-log .*/no/such/folder/m\.txt: cannot write it .*folder you can "
                                             r"write to") as e:
        M.MoveLog(str(tmp_path / "no" / "such" / "folder" / "m.txt"))
    assert isinstance(e.value, SphereError)


def test_a_line_cut_short_by_a_killed_daemon_is_left_out(tmp_path):
    path = tmp_path / "m.txt"
    path.write_text("100 250\n300 420\n500 6")
    assert M.read_move_log(path) == [(100, 250), (300, 420)]


def test_the_host_stage_splits_into_the_read_the_daemon_and_the_display():
    """Per onset the three parts add up to the host stage: the pty write -> the read -> the call -> the move seen. A
    move whose read came before the frame's write (a move of an earlier frame) gives no split."""
    ms = 1_000_000
    t0 = 10_000 * ms
    # onsets at 1 s and 2 s; the frames that carry them leave the UART 2 ms later and reach the pty 1 ms after that
    frames = [Frame(1.002, 1.0023, 1.0033, t0 + 1003_300_000 // 1000 * 1000, True),
              Frame(2.002, 2.0023, 2.0033, t0 + 2003_300_000 // 1000 * 1000, True)]
    seen = [frames[0].pty_ns + 700_000, frames[1].pty_ns + 900_000]
    samples = np.array([[t0, 0, 0], [seen[0], 5, 0], [seen[1], 9, 0]], dtype=np.int64)
    moves = [(frames[0].pty_ns + 40_000, frames[0].pty_ns + 300_000),  # read 0.04 ms after the write, called 0.26 later
             (frames[1].pty_ns - 5 * ms, frames[1].pty_ns + 500_000)]  # its read was before the write: no split
    got = attribute([1.0, 2.0], t0, frames, samples, t0, moves)
    host = got["ms"]["host"]
    assert host == pytest.approx([0.7, 0.9])
    parts = [got["ms"][k] for k in HOST_SPLIT]
    assert [len(p) for p in parts] == [1, 1, 1]
    assert [p[0] for p in parts] == pytest.approx([0.04, 0.26, 0.4])
    assert sum(p[0] for p in parts) == pytest.approx(host[0])
    assert set(attribute([1.0, 2.0], t0, frames, samples, t0)["ms"]) == {"age", "wire", "adapter", "host", "total", "lag"}
