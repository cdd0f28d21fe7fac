"""`sphere device` and `sphere monitor` against the real firmware on the virtual board over its pty: the
settings reach the firmware and change what it does (a 4 g knock is no tap with an 8 g threshold, and is
one with 2 g), the stream settings come back in its HELLO, identify and reboot are answered; the monitor
shows the packets, rates, flags, values, link quality and the events as they happen."""


import re
from pathlib import Path

import pytest

from sphere.cli import main
from sphere.sim import trace as T

from simscenarios import need_board, need_firmware, stop_simulator

#: the version the firmware's HELLO carries, as its source says (firmware/src/core/packets.h)
FIRMWARE_VERSION = ".".join(re.search(
    r"FIRMWARE_VERSION_MAJOR = (\d+), FIRMWARE_VERSION_MINOR = (\d+), FIRMWARE_VERSION_PATCH = (\d+)",
    (Path(__file__).resolve().parents[2] / "firmware" / "src" / "core" / "packets.h").read_text()).groups())

pytestmark = pytest.mark.slow

#: knocks every 1.5 s from 3 s on, a single and a double in turn (4 g each, as synthetic:taps), so whenever a
#: command lands, knocks follow within seconds however fast the board runs
KNOCKS_S = tuple(t for k in range(38) for t in ((3.0 + 1.5 * k,) if k % 2 == 0 else (3.0 + 1.5 * k, 3.15 + 1.5 * k)))
LISTEN_S = 4.0  # device seconds: at least two knocks


@pytest.fixture(scope="module")
def board(tmp_path_factory):
    from sphere.daemon.sources.base import SourceError

    from sphere.daemon.sources.simulated import start_simulator

    need_board()
    need_firmware()
    path = tmp_path_factory.mktemp("knocks") / "knocks.bin"
    T.to_chips(T.taps(60.0, at_s=KNOCKS_S)).write(path)
    try:
        proc, pty = start_simulator(str(path), seconds=60)
    except SourceError as e:
        pytest.fail(str(e))
    yield pty
    stop_simulator(proc)


def _events_for(pty, seconds):
    """Listen (DeviceLink on the pty) for ``seconds`` of the device's clock; the events heard."""
    from sphere.link.device import DeviceLink
    from sphere.link.port import open_port

    ser = open_port(pty)
    try:
        link, events, t0, t = DeviceLink(ser), [], None, None
        while t is None or t - t0 < seconds:
            for dp in link.read():
                if dp.packet.NAME == "RAW_SAMPLE":
                    t = dp.packet.t_us / 1e6
                    t0 = t if t0 is None else t0
                elif dp.packet.NAME == "EVENT":
                    events.append((dp.packet.t_us / 1e6, dp.packet.event_name))
        return events
    finally:
        ser.close()


def test_settings_change_what_the_firmware_does(board, capsys, tmp_path):
    assert main(["device", "--port", board, "get"]) == 0
    out = capsys.readouterr().out
    assert "(protocol 3); sensors found: adxl345, itg3200, hmc5883l" in out and "stream.status = on" in out
    assert "tap.duration_ms = 20 ms" in out  # every setting read back (GET_SETTINGS), the firmware's default here

    assert main(["device", "--port", board, "set", "tap.threshold_g=8", "stream.status=off"]) == 0
    cap = capsys.readouterr()
    assert "set: stream.status = off, tap.threshold_g = 8 g" in cap.out
    assert "firmware's default" not in cap.err  # the other tap keys kept as the sphere reports them
    assert main(["device", "--port", board, "get"]) == 0
    assert "stream.status = off" in capsys.readouterr().out  # the firmware's own HELLO says so

    assert _events_for(board, LISTEN_S) == []  # the 4 g knocks are under the 8 g threshold

    assert main(["device", "--port", board, "set", "tap.threshold_g=2"]) == 0
    capsys.readouterr()
    png = tmp_path / "monitor.png"
    # the next knocks are taps again: a single and a double knock give single_tap, single_tap + double_tap. Four
    # events hold a double tap wherever the threshold lands: between a double's two knocks the second is a single
    # tap, and so is the single knock after it (single, single, single, double: seen in a run on a loaded machine)
    assert main(["monitor", "--port", board, "--seconds", "120", "--events", "4", "--plot", "--plot-out", str(png)]) == 0
    out = capsys.readouterr().out
    assert "single_tap (z)" in out and "double_tap (z)" in out, out
    assert "HELLO seq" in out and f"firmware {FIRMWARE_VERSION}, protocol 3" in out
    for expected in ("RAW_SAMPLE", "ORIENTATION", "flags: accel_ok gyro_ok mag_ok", "accel g", "gyro °/s", "mag µT",
                     "orientation  heading", "link: frames ok", "CRC errors", "frames lost"):
        assert expected in out, (expected, out)
    assert png.stat().st_size > 10_000

    assert main(["device", "--port", board, "identify", "2"]) == 0
    assert "blinks for 2 s" in capsys.readouterr().out
    assert main(["device", "--port", board, "reboot"]) == 0
    assert f"rebooted; firmware {FIRMWARE_VERSION} is back" in capsys.readouterr().out


def test_bad_settings_are_one_line_and_touch_nothing(capsys):
    for argv, text in ((["set", "tap.treshold_g=3"], "did you mean tap.threshold_g?"),
                       (["set", "tap.threshold_g=30"], "0.0625 … 15.9375 g"),
                       (["set", "stream.raw_rate_hz=7"], "a divisor of 200"),
                       (["set", "board=nano"], "one of aligned, sen10724, gy85"),
                       (["set", "tap.axes=xq"], "letters from xyz"),
                       (["identify", "99"], "1 … 60")):
        assert main(["device", "--port", "/dev/nonexistent", *argv]) == 2  # a usage error (sphere-mouse.md, Exit status)
        err = capsys.readouterr().err
        assert err.startswith("sphere device: ") and text in err and err.count("\n") == 1, err
