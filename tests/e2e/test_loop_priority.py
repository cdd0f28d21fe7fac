"""sphere-mouse's loop asks the OS for a higher scheduling priority (sphere.daemon.priority), through the user's
path: the daemon on the virtual board's pty, its threads' scheduling read from /proc while it runs, its -v line and
its --print-stats line; where it is not allowed (CAP_SYS_NICE dropped) nothing breaks, and it says so once."""

from __future__ import annotations

import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import time

import pytest

from sphere.daemon.priority import thread_scheduling

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux scheduling")


@pytest.fixture(scope="module")
def board_pty(tmp_path_factory):
    from simscenarios import need_board, need_firmware

    from sphere.sim import trace as T
    from sphere.sim.board import board_command

    need_board()
    elf = need_firmware()
    tmp = tmp_path_factory.mktemp("priority")
    trace = T.to_chips(T.still(300.0)).write(tmp / "still.bin")
    board = subprocess.Popen(board_command(elf, trace, 300.0, pty=True, adapter="ftdi"),
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        yield next(line.split("UART on ", 1)[1].strip() for line in board.stdout if "UART on " in line)
    finally:
        board.kill()
        board.wait(10)


def fifo_allowed() -> bool:
    """CAP_SYS_NICE (bit 23 of the effective set) or an RLIMIT_RTPRIO hard limit of at least 5."""
    with open("/proc/self/status") as f:
        caps = next(int(line.split()[1], 16) for line in f if line.startswith("CapEff:"))
    hard = resource.getrlimit(resource.RLIMIT_RTPRIO)[1]
    return bool(caps & (1 << 23)) or hard == resource.RLIM_INFINITY or hard >= 5


def run_mouse(pty, tmp_path, *extra, prefix=()):
    """sphere-mouse -v --print-stats on the board (115200: no baud switch between runs) until it has found the
    sphere and read for 1.5 s; returns (its threads' scheduling while it ran: main first, stdout, stderr)."""
    err_path = tmp_path / "stderr.txt"
    with open(err_path, "w") as err:
        mouse = subprocess.Popen([*prefix, sys.executable, "-m", "sphere.mouse", "--port", pty, "--backend", "log",
                                  "--no-stream", "--quiet", "-v", "--config", os.devnull, "--print-stats",
                                  "--set", "source.baud_switch=0", *extra],
                                 stdout=subprocess.PIPE, stderr=err, text=True)
    try:
        deadline = time.monotonic() + 60
        while "sphere found on" not in err_path.read_text() and time.monotonic() < deadline and mouse.poll() is None:
            time.sleep(0.1)
        time.sleep(1.5)
        tids = sorted(int(t) for t in os.listdir(f"/proc/{mouse.pid}/task"))
        threads = [thread_scheduling(mouse.pid)] + [thread_scheduling(mouse.pid, t) for t in tids if t != mouse.pid]
        mouse.send_signal(signal.SIGTERM)
        out, _ = mouse.communicate(timeout=30)
    finally:
        if mouse.poll() is None:
            mouse.kill()
            mouse.wait(10)
    err = err_path.read_text()
    assert mouse.returncode == 0, err
    assert "sphere found on" in err, err
    return threads, out, err


def stats(out: str) -> tuple[int, str]:
    frames = int(re.search(r"sphere-mouse stats: frames (\d+)", out)[1])
    line = next(line for line in out.splitlines() if "scheduling of the port -> pointer loop: " in line)
    return frames, line.split("loop: ", 1)[1]


def test_the_loop_runs_in_real_time_where_allowed_and_nothing_else_does(board_pty, tmp_path):
    threads, out, err = run_mouse(board_pty, tmp_path)
    frames, said = stats(out)
    assert frames > 100, out
    if fifo_allowed():
        assert threads[0] == "SCHED_FIFO 5", threads
        assert "scheduling priority: SCHED_FIFO 5 for the port -> pointer loop" in err, err
    else:  # a lower nice value where RLIMIT_NICE allows, else as it was; said once at -v
        assert not threads[0].startswith("SCHED_FIFO"), threads
        assert err.count("scheduling priority: ") == 1, err
    assert said == threads[0], (said, threads)
    # no other thread of the daemon got it (SCHED_RESET_ON_FORK; the page's server, the output threads)
    assert all(t.startswith("SCHED_OTHER") for t in threads[1:]), threads


def test_not_allowed_changes_nothing_but_one_line_at_v(board_pty, tmp_path):
    """Without CAP_SYS_NICE (and the RLIMIT_RTPRIO/RLIMIT_NICE of 0 a user has by default) the daemon reads the
    sphere as before, and -v says once that the priority was not raised and where the docs say how to allow it."""
    setpriv = shutil.which("setpriv")
    if os.geteuid() != 0 or setpriv is None:
        pytest.skip("[optional] needs root and setpriv(1) to drop CAP_SYS_NICE (an unprivileged run is the test above)")
    if resource_allows_anyway():
        pytest.skip("[optional] this machine's limits allow a raised priority without CAP_SYS_NICE")
    threads, out, err = run_mouse(board_pty, tmp_path, prefix=(setpriv, "--bounding-set", "-sys_nice", "--"))
    frames, said = stats(out)
    assert frames > 100, out
    assert threads[0] == said and not threads[0].startswith("SCHED_FIFO") and " nice -" not in threads[0], threads
    lines = [line for line in err.splitlines() if "scheduling priority" in line]
    assert len(lines) == 1 and "not raised" in lines[0] and "Scheduling priority" in lines[0], err


def test_switched_off_by_the_setting(board_pty, tmp_path):
    threads, out, err = run_mouse(board_pty, tmp_path, "--set", "priority.enabled=false")
    frames, said = stats(out)
    assert frames > 100, out
    assert said.startswith("not asked") and not threads[0].startswith("SCHED_FIFO"), (said, threads)


def resource_allows_anyway() -> bool:
    rt = resource.getrlimit(resource.RLIMIT_RTPRIO)[1]
    nice = resource.getrlimit(resource.RLIMIT_NICE)[1]
    inf = resource.RLIM_INFINITY
    return rt == inf or rt >= 5 or nice == inf or nice > 20
