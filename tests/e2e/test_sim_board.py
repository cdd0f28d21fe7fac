"""The virtual board itself, checked with its own test sketch (hardware/sim/testfw): chip IDs and
register maps, the ADXL345's tap and free-fall engine, the byte stream, and fault injection.
These need no firmware, so they guard the board while the firmware changes."""

from __future__ import annotations

import json
import time

import pytest

from simscenarios import sketch_scenario


def test_board_answers_the_three_chips_ids():
    s = sketch_scenario("taps")
    h = s.summary.hello
    assert h is not None, s.stderr
    assert h.sensors_found == 7
    assert h.adxl345_devid == 0xE5 and h.itg3200_whoami & 0x7E == 0x68 and bytes(h.hmc5883l_id) == b"H43"


def test_capture_is_clean_and_samples_carry_the_trace():
    s = sketch_scenario("taps")
    d = s.summary.decoder
    assert d["crc_errors"] == 0 and d["seq_gaps"] == 0 and d["framing_errors"] == 0
    assert s.stats["frames_sent"] == d["frames_ok"]
    raw = s.summary.raw
    assert len(raw) >= 0.99 * 200 * 4 - 2
    # still, z up: 256 LSB/g on z, the field 20 µT north and 45 µT down in gain-1 LSB (x, y, z order)
    r = min(raw, key=lambda x: abs(x.t_us - 0.6e6))  # still: between power-up and the first tap at 1.0 s
    assert list(r.accel) == [0, 0, 256]
    assert list(r.gyro) == [0, 0, 0]
    assert list(r.mag) == [0, round(20 * 10.9), round(-45 * 10.9)]


def test_tap_engine_single_and_double_tap():
    s = sketch_scenario("taps")
    ev = s.summary.events
    singles = [e.t_us / 1e6 for e in ev if e.event_name == "single_tap"]
    doubles = [e.t_us / 1e6 for e in ev if e.event_name == "double_tap"]
    assert any(abs(t - 1.0) < 0.1 for t in singles), ev
    assert any(abs(t - 2.0) < 0.1 for t in singles), ev
    assert any(abs(t - 2.15) < 0.1 for t in doubles), ev
    assert all(e.act_tap_status & 0x07 == 0x01 for e in ev)  # z axis


def test_free_fall_engine_on_a_toss():
    s = sketch_scenario("toss")
    ff = [e.t_us / 1e6 for e in s.summary.events if e.event_name == "free_fall"]
    assert ff and 2.0 <= ff[0] <= 2.4, ff


def test_nack_fault_and_recovery():
    s = sketch_scenario("nack")
    raw = s.summary.raw
    during = [r for r in raw if 1.7 < r.t_us / 1e6 < 2.9]
    after = [r for r in raw if r.t_us / 1e6 > 3.2]
    before = [r for r in raw if 0.5 < r.t_us / 1e6 < 1.4]
    assert before and all(r.flags & 0x02 for r in before)
    assert during and not any(r.flags & 0x02 for r in during)
    assert after and all(r.flags & 0x02 for r in after)
    assert s.stats["chip_nacks"]["itg3200"] > 0 and s.stats["i2c_errors"] > 0


def test_bus_stall_is_survived():
    s = sketch_scenario("stall")
    raw = s.summary.raw
    assert any(r.t_us / 1e6 > 2.0 for r in raw), "no samples after the stall"
    assert any(not (r.flags & 0x07 == 0x07) for r in raw if 1.5 < r.t_us / 1e6 < 1.7), "the stall was not seen"


STATS_KEYS = {"cycles_per_update", "cycles_per_loop", "cpu_load", "overruns", "frames_sent", "i2c_transactions",
              "i2c_errors", "simulated_seconds"}


def test_sphere_sim_command_writes_the_stats(tmp_path, capsys):
    import json

    from sphere.cli import main
    from simscenarios import need_board, need_testfw

    need_board()
    need_testfw()
    stats = tmp_path / "stats.json"
    cap = tmp_path / "cap.bin"
    rc = main(["sim", "--trace", "synthetic:rotation:90", "--seconds", "2", "--firmware", "testfw",
               "--capture", str(cap), "--stats", str(stats)])
    assert rc == 0
    d = json.loads(stats.read_text())
    assert STATS_KEYS <= set(d)
    for k in ("cycles_per_update", "cycles_per_loop"):
        assert {"min", "median", "max"} <= set(d[k]) and d[k]["median"] > 0
    assert 0 < d["cpu_load"] < 1
    assert d["simulated_seconds"] == pytest.approx(2.0)
    assert d["frames_sent"] > 350 and d["i2c_errors"] == 0
    assert cap.stat().st_size > 0
    out = capsys.readouterr().out
    assert "cycles per MARG update" in out
    # the rotation reached the gyro: 90 °/s about z after the first second
    from sphere.sim.analysis import summarise

    raw = summarise(cap).raw
    late = [r for r in raw if r.t_us > 1.2e6]
    assert late and all(r.gyro[2] == round(90 * 14.375) for r in late)


def test_pty_works_with_sphere_capture(tmp_path):
    """The UART as a pseudo-terminal, paced in real time, read by `sphere capture` unmodified."""
    import re
    import subprocess

    from sphere.cli import main
    from sphere.protocol.decoder import decode_all
    from sphere.sim import trace as T
    from sphere.sim.board import board_command
    from simscenarios import need_board, need_testfw

    need_board()
    elf = need_testfw()
    trace = T.to_chips(T.still(6.0)).write(tmp_path / "still.bin")
    proc = subprocess.Popen(board_command(elf, trace, 6.0, pty=True), stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    try:
        port = None
        for line in proc.stdout:
            m = re.search(r"sphere-board: UART on (/dev/pts/\d+)", line)
            if m:
                port = m.group(1)
                break
        assert port, "the board did not print its pty"
        out = tmp_path / "pty.bin"
        assert main(["capture", "--port", port, "--out", str(out), "--seconds", "2", "--quiet"]) == 0
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    packets, stats = decode_all(out.read_bytes())
    # joining a running stream, the first chunk may be the tail of a frame: the decoder drops it (spec §2.1)
    assert stats.crc_errors + stats.framing_errors <= 1 and stats.bytes_skipped < 66
    assert stats.frames_ok > 100 and stats.seq_gaps == 0  # about 200 frames a second in real time, none lost


def test_send_delivers_bytes_to_the_uart(tmp_path):
    from sphere.sim import trace as T
    from sphere.sim.analysis import summarise
    from sphere.sim.board import run_board
    from simscenarios import need_board, need_testfw

    need_board()
    elf = need_testfw()
    trace = T.to_chips(T.still(2.5)).write(tmp_path / "still.bin")
    send = tmp_path / "send.txt"
    send.write_text("# seconds, bytes\n0.5 01 02 03 04 05\n1.2 " + " ".join(["aa"] * 100) + "\n")
    cap = tmp_path / "cap.bin"
    r = run_board(elf, trace, 2.5, cap, send=send)
    assert r.returncode == 0, r.stderr
    st = summarise(cap).status
    # the sketch reports the bytes it received in STATUS rx_errors
    assert [x.rx_errors for x in st] == [5, 105], [(x.t_us, x.rx_errors) for x in st]


def test_the_board_stops_when_sphere_sim_is_killed():
    """`sphere sim --pty` runs the board as its child; killing `sphere sim` (or the daemon that started
    it) must not leave the board holding the pty and a core until its --seconds are over: the board
    asks the kernel for SIGTERM when its parent goes (PR_SET_PDEATHSIG) and stops as on SIGTERM."""
    import signal

    from simscenarios import children, need_board, need_firmware, survivors
    from sphere.daemon.sources.base import SourceError

    from sphere.daemon.sources.simulated import start_simulator

    need_board()
    need_firmware()
    try:
        proc, _ = start_simulator("synthetic:still", seconds=120)
    except SourceError as e:
        pytest.fail(str(e))
    try:
        kids = children(proc.pid)
        assert kids, "sphere sim started no board"
        proc.send_signal(signal.SIGKILL)  # no chance to clean up: only the kernel can tell the board
        proc.wait(5)

        left = survivors(kids)
        assert not left, "the board kept running after sphere sim was killed"
    finally:
        if proc.poll() is None:
            proc.kill()


def test_usb_serial_adapters_deliver_in_packets(tmp_path):
    """--adapter: the host gets the same bytes, later and in packets: an FTDI FT232R sends 62 data bytes
    at once or what it holds when its 16 ms latency timer runs out (FTDI AN232B-04); the CH340 model sends
    at each 1 ms USB frame. --capture-times gives the time each frame's delimiter reached the host."""
    import numpy as np

    from sphere.sim import trace as T
    from sphere.sim.board import run_board
    from simscenarios import need_board, need_testfw

    need_board()
    elf = need_testfw()
    trace = T.to_chips(T.still(2.0)).write(tmp_path / "still.bin")
    got = {}
    for adapter in (None, "ftdi", "ch340"):
        cap, times = tmp_path / f"{adapter}.cap", tmp_path / f"{adapter}.times"
        r = run_board(elf, trace, 2.0, cap, capture_times=times, **({"adapter": adapter} if adapter else {}))
        assert r.returncode == 0, r.stderr
        rec = np.frombuffer(times.read_bytes(), dtype=[("off", "<u8"), ("t", "<f8")])
        got[adapter] = (cap.read_bytes(), rec["t"])
    wire = got[None][1]
    for adapter, (most, least) in (("ftdi", (0.017, 0.002)), ("ch340", (0.0011, 0.0))):
        data, t = got[adapter]
        assert data == got[None][0]
        delay = t - wire
        assert delay.min() >= 0 and delay.max() <= most and delay.mean() >= least, (adapter, delay.max(), delay.mean())
    assert len(np.unique(got["ftdi"][1])) < 0.6 * len(wire)  # frames share packets


def test_ftdi_model_flushes_at_1_ms_once_the_host_asks_for_low_latency(tmp_path):
    """The seam of the low-latency request (hardware/sim/README.md, "The host's requests"): the host opens the
    board's pty the way sphere-mouse does (``open_port(low_latency=True)``: ASYNC_LOW_LATENCY, which a pty
    refuses, then CMSPAR in its termios); from then on the FTDI model's latency timer is 1 ms instead of 16 ms,
    as ftdi_sio sets it. Frames are compared with the same firmware's UART times (no adapter, no pty)."""
    import subprocess

    import numpy as np
    import serial

    from sphere.link.port import open_port
    from sphere.sim import trace as T
    from sphere.sim.board import board_command, run_board
    from simscenarios import need_board, need_testfw

    need_board()
    elf = need_testfw()
    trace = T.to_chips(T.still(3.0)).write(tmp_path / "still.bin")
    wire_cap, wire_times = tmp_path / "wire.cap", tmp_path / "wire.times"
    r = run_board(elf, trace, 3.0, wire_cap, capture_times=wire_times)
    assert r.returncode == 0, r.stderr
    cap, times, stats = tmp_path / "ftdi.cap", tmp_path / "ftdi.times", tmp_path / "stats.json"
    cmd = board_command(elf, trace, 3.0, capture=cap, capture_times=times, pty=True, adapter="ftdi", stats=stats)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = ""
        while "UART on /dev/pts/" not in line:
            line = proc.stdout.readline()
            assert line, proc.stderr.read()
        time.sleep(1.2)  # the driver's default first
        ser = open_port(line.split()[-1], reset_on_open=False, low_latency=True)
        assert ser.low_latency_problem is None
        deadline = time.monotonic() + 10
        try:
            while proc.poll() is None and time.monotonic() < deadline:
                ser.read(4096)
        except serial.SerialException:  # the board ended: its pty went away
            pass
        ser.close()
        assert proc.wait(10) == 0, proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
    events = [f for f in json.loads(stats.read_text())["faults"] if f["kind"].startswith("host_")]
    assert [e["kind"] for e in events] == ["host_low_latency"], events
    asked = events[0]["t"]
    assert 0.1 < asked < 2.7  # simulated time: a loaded machine runs the board slower than the wall clock
    assert cap.read_bytes() == wire_cap.read_bytes()
    rec = np.dtype([("off", "<u8"), ("t", "<f8")])
    wire, host = np.fromfile(wire_times, rec)["t"], np.fromfile(times, rec)["t"]
    delay = host - wire
    before, after = delay[wire < asked - 0.02], delay[wire > asked + 0.02]
    assert before.max() > 0.008  # frames waited for the 16 ms timer
    assert after.max() <= 0.0021, after.max()  # the 1 ms timer, counted from the last packet, at 1 ms USB frames
    assert before.max() > 4 * after.max()


def test_pty_leaves_the_fixed_simavr_name_alone(tmp_path):
    """simavr's uart_pty points /tmp/simavr-uart0 at its pty; the board puts back what was there (another
    run's link) and leaves nothing of its own: a fixed name in /tmp is not ours to rewrite."""
    import os
    import subprocess

    from sphere.sim import trace as T
    from sphere.sim.board import board_command
    from simscenarios import need_board, need_testfw

    need_board()
    elf = need_testfw()
    trace = T.to_chips(T.still(1.0)).write(tmp_path / "still.bin")
    link = "/tmp/simavr-uart0"
    saved = os.readlink(link) if os.path.islink(link) else None

    def run_board():
        out = subprocess.run(board_command(elf, trace, 0.5, pty=True), capture_output=True, text=True, timeout=60)
        assert "UART on /dev/pts/" in out.stdout, out.stdout + out.stderr

    try:
        if saved is not None:
            os.unlink(link)
        other = str(tmp_path / "another-simulators-pty")
        os.symlink(other, link)
        run_board()
        assert os.path.islink(link) and os.readlink(link) == other
        os.unlink(link)
        run_board()
        assert not os.path.lexists(link)
    finally:
        if os.path.islink(link):
            os.unlink(link)
        if saved is not None:
            os.symlink(saved, link)


def test_restarts_are_neither_overruns_nor_a_faster_stream(tmp_path, capsys):
    """A brown-out and a power-off restart the firmware: the stream's rate is counted per run of the device's
    clock (it starts again at each restart), and the pause while it restarts is no overrun of the timing pin."""
    import json

    from sphere.cli import main
    from simscenarios import need_board, need_firmware

    need_board()
    fw = need_firmware()
    stats = tmp_path / "stats.json"
    rc = main(["sim", "--no-build", "--firmware", str(fw), "--trace", "synthetic:still", "--seconds", "4.5",
               "--brownout", "1.5", "--power-off", "3", "--stats", str(stats)])
    assert rc == 0
    d = json.loads(stats.read_text())
    assert [f["kind"] for f in d["faults"] if f["kind"] in ("brownout", "power_off")] == ["brownout", "power_off"]
    assert d["overruns"] == 0
    s = d["stream"]
    assert s["hellos"] == 3
    assert s["raw_rate_hz"] == pytest.approx(200.0, rel=0.002)
    assert s["orientation_rate_hz"] == pytest.approx(100.0, rel=0.002)
    assert "raw " in capsys.readouterr().out


def test_stream_rate_spans_add_up_over_restarts_and_the_clock_wrap():
    from types import SimpleNamespace as P

    from sphere.sim.analysis import CaptureSummary

    wrap = 1 << 32
    run1 = [P(t_us=(wrap - 20_000 + 5_000 * i) % wrap) for i in range(9)]  # 200 Hz across the u32 wrap
    run2 = [P(t_us=1_000 + 5_000 * i) for i in range(5)]  # restarted: the clock begins again, behind run1's end
    assert CaptureSummary.rate_hz(run1) == pytest.approx(200.0)
    assert CaptureSummary.rate_hz(run1 + run2) == pytest.approx(200.0)
    assert CaptureSummary.rate_hz(run2[1:2] + run2[:1]) is None  # one packet in each run: no interval
