"""SET_BAUD through the user's path: sphere-mouse's serial source on the virtual board (which garbles bytes whose
two ends run at different rates) moves the link to 1,000,000 baud, back to 115200 when the sphere resets, and up
again at the restarted sphere's HELLO; a confirming ECHO the sphere got garbled is sent again and nothing is lost."""

from __future__ import annotations

import contextlib
import json
import subprocess
import threading
import time


@contextlib.contextmanager
def daemon_on_board(tmp_path, seconds, wrap_port=None, **board_kw):
    """sphere-mouse's daemon with its serial source (switching to 1,000,000 baud) on the virtual board's pty, a still
    sphere; yields (source, the source's log lines); ``wrap_port`` wraps the port the source opens."""
    from simscenarios import need_board, need_firmware

    from sphere.daemon.app import SphereMouse
    from sphere.daemon.backends.memory import RecordingBackend
    from sphere.daemon.config import Config
    from sphere.daemon.sources.serial import SerialSource
    from sphere.sim import trace as T
    from sphere.sim.board import board_command

    class Source(SerialSource):
        def _open(self, path):
            ser = super()._open(path)
            return wrap_port(ser) if wrap_port else ser

    need_board()
    elf = need_firmware()
    trace = T.to_chips(T.still(seconds)).write(tmp_path / "still.bin")
    board = subprocess.Popen(board_command(elf, trace, seconds, pty=True, **board_kw),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines = []
    try:
        pty = next(line.split("UART on ", 1)[1].strip() for line in board.stdout if "UART on " in line)
        src = Source(pty, hello_timeout_s=0.3, discovery_timeout_s=5.0, link_timeout_s=3.0,
                     reconnect_interval_s=0.2, baud_switch=1000000, log=lines.append)
        cfg = Config().with_overrides({"outputs.page": {"enabled": False}}, "test")
        daemon = SphereMouse(cfg, src, RecordingBackend(), log=lambda m: None)
        t = threading.Thread(target=daemon.run, daemon=True)
        t.start()
        yield src, lines
        daemon.stop()
        t.join(5)
    finally:
        board.terminate()
        board.wait(10)


def test_sphere_mouse_switches_the_virtual_board_to_1m_and_follows_a_reset_back(tmp_path):
    with daemon_on_board(tmp_path, 40.0, adapter="ftdi", reset_at=(8.0,)) as (src, lines):
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


class _LateRate:
    """A serial port whose first change of rate takes effect only after the next write has gone out at the old one:
    the confirming ECHO leaves before the sphere's UART switched, as when the host reacts to SET_BAUD's REPLY within
    a byte time (or the virtual board lags the wall clock), and the sphere receives it garbled."""

    def __init__(self, ser):
        self._ser = ser
        self._pending = None
        self._late = True

    def __getattr__(self, name):
        return getattr(self._ser, name)

    @property
    def baudrate(self):
        return self._ser.baudrate

    @baudrate.setter
    def baudrate(self, baud):
        if self._late and baud != self._ser.baudrate:
            self._late, self._pending = False, baud
        else:
            self._ser.baudrate = baud

    def write(self, data):
        if self._pending is None:
            return self._ser.write(data)
        time.sleep(0.15)  # the sphere has switched by now (it does once SET_BAUD's REPLY has left its UART)
        n = self._ser.write(data)
        self._ser.flush()
        time.sleep(0.1)  # and the board has taken these bytes in, at the old rate
        self._ser.baudrate, self._pending = self._pending, None
        return n


def test_a_garbled_confirmation_is_sent_again_and_nothing_is_lost(tmp_path):
    """The first ECHO at 1,000,000 baud reaches the sphere before its UART switched (garbled): sphere-mouse's serial
    source sends it again (after a 0x00) and the link is at 1,000,000 with no frame lost. Before, the source waited 1 s
    for a REPLY to that one ECHO, gave up ("no answer") at about the moment the sphere fell back by itself, and lost
    the frames the sphere sent at 115200 while the port still listened at 1,000,000."""
    stats = tmp_path / "stats.json"
    with daemon_on_board(tmp_path, 30.0, wrap_port=_LateRate, stats=stats) as (src, lines):
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not any("baud" in line for line in lines):
            time.sleep(0.1)
        time.sleep(3.0)  # longer than the sphere's own 1 s fall-back and the 1.5 s lease
    said = "\n".join(lines)
    assert not any("no answer" in line for line in lines), said
    assert any("link at 1000000 baud" in line for line in lines), said
    assert src.link_baud == 1000000, said
    s = src.stats
    assert s.frames_ok > 400, said  # streaming, at 1,000,000 since the switch
    assert (s.seq_gaps, s.frames_lost, s.crc_errors, s.framing_errors) == (0, 0, 0, 0), (s, said)
    garbled = json.loads(stats.read_text())
    assert garbled["garbled_bytes_to_device"] > 0  # the first ECHO did reach the sphere garbled
    assert garbled["garbled_bytes_to_host"] == 0
