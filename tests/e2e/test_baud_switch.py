"""SET_BAUD through the user's path: sphere-mouse's serial source on the virtual board (which garbles bytes whose
two ends run at different rates) moves the link to 1,000,000 baud, back to 115200 when the sphere resets, and up
again at the restarted sphere's HELLO."""

from __future__ import annotations

import subprocess
import threading
import time



def test_sphere_mouse_switches_the_virtual_board_to_1m_and_follows_a_reset_back(tmp_path):
    from simscenarios import need_board, need_firmware

    from sphere.daemon.app import SphereMouse
    from sphere.daemon.backends.memory import RecordingBackend
    from sphere.daemon.config import Config
    from sphere.daemon.sources.serial import SerialSource
    from sphere.sim import trace as T
    from sphere.sim.board import board_command

    need_board()
    elf = need_firmware()
    trace = T.to_chips(T.still(40.0)).write(tmp_path / "still.bin")
    board = subprocess.Popen(board_command(elf, trace, 40.0, pty=True, adapter="ftdi", reset_at=(8.0,)),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines = []
    try:
        pty = next(line.split("UART on ", 1)[1].strip() for line in board.stdout if "UART on " in line)
        src = SerialSource(pty, hello_timeout_s=0.3, discovery_timeout_s=5.0, link_timeout_s=3.0,
                           reconnect_interval_s=0.2, baud_switch=1000000, log=lines.append)
        cfg = Config().with_overrides({"outputs.page": {"enabled": False}}, "test")
        daemon = SphereMouse(cfg, src, RecordingBackend(), log=lambda m: None)
        t = threading.Thread(target=daemon.run, daemon=True)
        t.start()
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not any("link at 1000000 baud" in line for line in lines):
            time.sleep(0.1)
        assert any("link at 1000000 baud" in line for line in lines), lines
        at_switch = src.stats.frames_ok
        errors, gaps = src.stats.crc_errors, src.stats.seq_gaps  # the open may cut a frame: counted before
        time.sleep(2.0)
        assert src.link_baud == 1000000 and src.stats.frames_ok > at_switch + 200  # streaming at the new rate
        assert src.stats.crc_errors == errors and src.stats.seq_gaps == gaps
        # the sphere resets at 8 s (simulated): it starts at 115200 again; the port follows within 0.5 s
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not any("back to 115200" in line for line in lines):
            time.sleep(0.1)
        assert any("back to 115200" in line for line in lines), lines
        # its HELLO at 115200 (a restart) has the link moved up again
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and sum("link at 1000000 baud" in line for line in lines) < 2:
            time.sleep(0.1)
        assert sum("link at 1000000 baud" in line for line in lines) == 2, "\n".join(lines)
        after = src.stats.frames_ok
        time.sleep(2.0)
        assert src.link_baud == 1000000 and src.stats.frames_ok > after + 100, lines
        daemon.stop()
        t.join(5)
    finally:
        board.terminate()
        board.wait(10)
