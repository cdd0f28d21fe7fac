"""Every device setting read back and kept over a power cycle, on the real firmware in the virtual board:
`sphere device set` of every key `sphere device keys` lists, `sphere device save`, the supply cut and back
(`sphere sim --power-off`: a power-on reset, RAM lost, the EEPROM kept as on the ATmega328P), and `sphere
device get` reads every value back equal, saying they are the saved ones (protocol/spec.md §5.3)."""

import re
import time

import pytest

from sphere.cli import main

from simscenarios import need_board, need_firmware, stop_simulator

pytestmark = pytest.mark.slow

POWER_OFF_S = 12.0  # device seconds: the commands below take a few; the board runs in real time with --pty
#: a value for every key, none of them the firmware's default (firmware/src/core: adxl345.cpp, marg_filter.h)
EVERY_KEY = ["stream.raw=on", "stream.orientation=on", "stream.status=off", "stream.raw_rate_hz=100",
             "stream.orientation_rate_hz=50", "tap.threshold_g=2.5", "tap.duration_ms=25", "tap.latency_ms=50",
             "tap.window_ms=250", "tap.axes=z", "free_fall.threshold_g=0.5", "free_fall.time_ms=100",
             "filter.beta=0.06", "board=sen10724"]


def _get(port, capsys) -> dict:
    assert main(["device", "--port", port, "get"]) == 0
    out = capsys.readouterr().out
    return out, dict(re.findall(r"^([a-z_.]+) = (.+)$", out, re.M))


def _power_cycled(port, deadline_s: float) -> bool:
    """Wait for the HELLO of a power-on reset (seq 0, reset_cause power_on)."""
    from sphere.link.device import DeviceLink
    from sphere.link.port import open_port

    ser = open_port(port)
    try:
        link, end = DeviceLink(ser), time.monotonic() + deadline_s
        while time.monotonic() < end:
            for dp in link.read():
                p = dp.packet
                if p.NAME == "HELLO" and p.seq == 0 and p.reset_cause & 1:
                    return True
        return False
    finally:
        ser.close()


def test_every_setting_is_read_back_and_kept_over_a_power_cycle(capsys):
    from sphere.daemon.sources.base import SourceError
    from sphere.daemon.sources.simulated import start_simulator
    from sphere.link.device_settings import SETTINGS

    need_board()
    need_firmware()
    assert {item.split("=")[0] for item in EVERY_KEY} == set(SETTINGS)
    try:
        proc, pty = start_simulator("synthetic:still", seconds=60, extra=("--power-off", f"{POWER_OFF_S:g}"))
    except SourceError as e:
        pytest.fail(str(e))
    try:
        out, before = _get(pty, capsys)
        assert "nothing saved" in out  # a new board: an erased EEPROM
        assert main(["device", "--port", pty, "set", *EVERY_KEY]) == 0
        assert "sent as the firmware's default" not in capsys.readouterr().err  # the sphere reports every key
        assert main(["device", "--port", pty, "save"]) == 0
        capsys.readouterr()
        out, saved = _get(pty, capsys)
        assert "saved on the sphere" in out
        assert saved == {"stream.raw": "on", "stream.orientation": "on", "stream.status": "off",
                         "stream.raw_rate_hz": "100 Hz", "stream.orientation_rate_hz": "50 Hz",
                         "tap.threshold_g": "2.5 g", "tap.duration_ms": "25 ms", "tap.latency_ms": "50 ms",
                         "tap.window_ms": "250 ms", "tap.axes": "z", "free_fall.threshold_g": "0.5 g",
                         "free_fall.time_ms": "100 ms", "filter.beta": "0.06", "board": "sen10724"}
        assert saved != before
        assert _power_cycled(pty, POWER_OFF_S + 20), "no power-on HELLO after --power-off"
        out, after = _get(pty, capsys)
        assert after == saved
        assert "saved on the sphere" in out
        # cleared: the next power-up would use the defaults; the settings in use stay
        assert main(["device", "--port", pty, "clear"]) == 0
        out, cleared = _get(pty, capsys)
        assert cleared == saved and "nothing saved" in out
    finally:
        stop_simulator(proc)


def test_the_daemons_device_settings_reach_the_firmware_at_connect():
    """sphere-mouse's [device] settings are sent at every connect and the firmware acts on them: with
    ``stream.raw_rate_hz=50`` the RAW_SAMPLEs that follow come at 50 Hz, not the 200 Hz default."""
    from sphere.daemon.config import Config
    from sphere.daemon.sources.simulated import SimulatorSource

    need_board()
    need_firmware()
    cfg = Config().with_overrides({"device": {"settings": ["stream.raw_rate_hz=50", "tap.axes=z"]},
                                   "source.simulate": {"trace": "synthetic:still", "seconds": 20.0}}, "test")
    logs = []
    src = SimulatorSource.from_settings(cfg["source.simulate"], logs.append, cfg)
    times = []
    try:
        for batch in src:
            times += [dp.t_us for dp in batch if dp.packet.NAME == "RAW_SAMPLE"]
            if len(times) > 2 and times[-1] - times[0] > 3e6:
                break
    finally:
        src.close()
    assert any("[device] settings sent: stream.raw_rate_hz = 50 Hz, tap.axes = z" in m for m in logs), logs
    late = [t for t in times if t > times[0] + 1e6]  # after the settings took effect
    rate = (len(late) - 1) / ((late[-1] - late[0]) / 1e6)
    assert abs(rate - 50) < 2, rate
