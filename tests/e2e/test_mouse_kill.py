"""sphere-mouse --simulate killed with SIGKILL leaves nothing running (issue 14 item 8): the virtual board's
`sphere sim` gets SIGTERM from the kernel when the daemon goes (PR_SET_PDEATHSIG), and the board when `sphere sim`
goes. Before, `sphere sim` ran on for up to its 600 s."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from simscenarios import children, need_board, need_firmware, survivors


def test_sigkill_of_the_daemon_stops_the_virtual_board(tmp_path):
    need_board()
    need_firmware()
    env = {**os.environ, "XDG_CONFIG_HOME": str(tmp_path)}
    daemon = subprocess.Popen([sys.executable, "-m", "sphere.mouse", "--simulate", "--backend", "log", "--no-stream",
                               "--quiet", "--set", "source.simulate.seconds=30"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
    family: list[int] = []
    try:
        deadline = time.monotonic() + 120  # the first run may build the board
        while time.monotonic() < deadline:
            sim = children(daemon.pid)
            family = sim + [g for s in sim for g in children(s)]
            if len(family) >= 2:  # `sphere sim` and its board
                break
            assert daemon.poll() is None, daemon.stderr.read()
            time.sleep(0.2)
        assert len(family) >= 2, "the daemon did not start `sphere sim` and its board"
        daemon.send_signal(signal.SIGKILL)  # no chance to clean up
        daemon.wait(5)
        left = survivors(family)
        assert not left, "the virtual board outlived the daemon"
    finally:
        if daemon.poll() is None:
            daemon.kill()


def test_a_virtual_board_killed_mid_run_ends_the_daemon_with_exit_1(tmp_path):
    """The simulated sphere's board dies during the run (killed, crashed): one line saying so in the simulator's
    words, the daemon's last line, exit status 1 (a device that failed during the run). It was 'the simulated
    sphere stopped (exit status 247)' and exit status 0, as for a run that was over."""
    need_board()
    need_firmware()
    env = {**os.environ, "XDG_CONFIG_HOME": str(tmp_path)}
    daemon = subprocess.Popen([sys.executable, "-m", "sphere.mouse", "--simulate", "--backend", "log", "--no-stream",
                               "--quiet", "--set", "source.simulate.seconds=60"], stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, text=True, env=env)
    try:
        seen = []
        for line in daemon.stderr:  # the link is up: the board runs and the daemon reads it
            seen.append(line)
            if "sphere found on" in line:
                break
        sim = children(daemon.pid)
        board = [g for s in sim for g in children(s)]
        assert len(sim) == 1 and len(board) == 1, ("no `sphere sim` and board under the daemon", seen)
        time.sleep(0.5)
        os.kill(board[0], signal.SIGKILL)
        _, err = daemon.communicate(timeout=30)
        err = "".join(seen) + err
        assert daemon.returncode == 1 and "Traceback" not in err, (daemon.returncode, err)
        assert "the simulated sphere stopped before its 60 s were over (sphere sim: the board exited with -9)" in err, err
        assert err.rstrip().splitlines()[-1].startswith("sphere-mouse: stopped:"), err
    finally:
        if daemon.poll() is None:
            daemon.kill()
            daemon.wait()
