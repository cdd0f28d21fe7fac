"""--simulate: the virtual board is started as `sphere sim --trace T --pty`, its pty path read from its
output, and the daemon ends when the board does. A stand-in board (a small script printing the same
line as hardware/sim's sphere-board) keeps this test independent of the firmware build."""

from __future__ import annotations

import sys
import textwrap

import pytest

from sphere.daemon.sources import simulated
from sphere.daemon.sources.base import SourceError
from sphere.daemon.app import SphereMouse
from sphere.daemon.backends.memory import RecordingBackend
from sphere.daemon.config import Config

BOARD = textwrap.dedent('''
    import os, sys, time, tty, select
    from sphere.daemon.scripted_sphere import ScriptedSphere, hello_packet
    from sphere.protocol import FrameDecoder
    master, slave = os.openpty()
    tty.setraw(slave)
    print("some build output")
    print("sphere-board: UART on " + os.ttyname(slave), flush=True)
    dec = FrameDecoder("host")
    while True:  # like Bluetooth: answer GET_HELLO
        r, _, _ = select.select([master], [], [], 0.05)
        if r and any(p.NAME == "GET_HELLO" for p in dec.feed(os.read(master, 256))):
            break
    s = ScriptedSphere()
    os.write(master, s.frame(hello_packet()))
    for _, f in s.steps([("still", 0.5), ("turn", (0, 0, 1), 10.0, 0.5), ("still", 0.3)]):
        os.write(master, f)
    time.sleep(0.5)
''')


def test_simulate_runs_the_board_and_ends_with_it(tmp_path, monkeypatch):
    script = tmp_path / "board.py"
    script.write_text(BOARD)
    seen = {}

    def command(trace="", seconds=0, extra=()):
        seen["trace"] = trace
        return [sys.executable, str(script)]

    monkeypatch.setattr(simulated, "simulator_command", command)
    logs = []
    src = simulated.SimulatorSource("synthetic:taps", log=logs.append, hello_timeout_s=0.1, link_timeout_s=5.0,
                                  reconnect_interval_s=0.1)
    backend = RecordingBackend()
    cfg = Config().with_overrides({"outputs.page": {"enabled": False}}, "t")
    SphereMouse(cfg, src, backend, log=lambda m: None).run()  # returns once the board has exited
    src.close()
    assert seen["trace"] == "synthetic:taps"
    assert abs(backend.x + 240) <= 2  # 5° left at 1920 px / 40°
    assert any("simulated sphere's run is over" in m for m in logs), logs
    assert not any("lost the sphere" in m for m in logs), logs  # the end of the run is not a lost link


def test_simulator_that_fails_says_why(tmp_path, monkeypatch):
    script = tmp_path / "broken.py"
    script.write_text("print('make: *** [Makefile:68: build/sphere.elf] Error 1'); raise SystemExit(2)\n")
    monkeypatch.setattr(simulated, "simulator_command", lambda trace="", seconds=0, extra=(): [sys.executable, str(script)])
    with pytest.raises(SourceError, match="did not open its pty: make: .*Error 1"):
        simulated.SimulatorSource()


def test_simulator_command_is_sphere_sim_pty():
    cmd = simulated.simulator_command("", 60)
    assert simulated.simulator_command()[-1] == "600"
    assert cmd[1:] == ["-m", "sphere.cli", "sim", "--trace", "synthetic:tour", "--pty", "--seconds", "60"]
