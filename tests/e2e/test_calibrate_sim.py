"""`sphere calibrate --port` against the virtual sphere: the real firmware image on the simulated board
(hardware/sim), its UART on a pseudo-terminal read by pyserial, turned as the guided steps ask by
`synthetic:calibration` (still, turns about each axis, six faces, tumbling) with known sensor imperfections.
The board is a GY-85 or a SparkFun sensor stick (`--board`: the chips mounted as on those boards); the
firmware's board profile is the right one (SET_BOARD at 0.5 s, as the owner sends it once) or left at
`aligned`, and the axis check must tell which chip is mounted how.

Tolerances, from the chips' quantisation and the simulated noise (datasheet-like, sphere.sim.trace):
- gyro bias: the mean of a 3 s still window, 600 samples of 5.5 LSB RMS noise → σ 0.2 LSB, then rounded
  to an integer LSB (±0.5): within 1 LSB (0.07 °/s).
- accelerometer offset: each face is the mean of ≥ 400 samples of 1–1.5 LSB noise (σ ≤ 0.08 LSB) and
  the six-position fit is exact for six poses, then rounded (±0.5): within 1 LSB (3.9 mg).
- accelerometer scale: the same mean errors over 2 g span move a gain by < 1e-3 (Q14: < 16), plus
  rounding to Q14 (±0.5): within 20 Q14 units (0.12 %).
- magnetometer hard iron: an ellipsoid fit over ~1000+ readings of 2 LSB noise and integer quantisation
  (the HMC5883L's 0.092 µT LSB): within 2 LSB (0.18 µT); soft iron: the recovered matrix times the
  injected one is a multiple of the identity within 0.01.
"""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from simscenarios import need_board, need_firmware, stop_simulator

from sphere import chips
from sphere.sim import trace as T

CAL_SIM_S = 90  # simulated seconds: the session needs about 60, the rest is room for a slow machine
AXES_SIM_S = 30  # the session stops at the axis check, about 16 s in
TIMEOUT_S = 90  # per step, wall time (the board runs 0.7–2.5 simulated s per wall s, paced to ≤ 1)


def _start(trace: str, seconds: float, board: str | None = None, profile: str | None = None, tmp=None,
           monkeypatch=None):
    """The virtual sphere on a pty (as sphere-mouse --simulate starts it), on ``board`` with the firmware
    told ``profile`` by SET_BOARD at 0.5 s (none: the firmware's default, aligned)."""
    from sphere.daemon.sources.base import SourceError
    from sphere.daemon.sources.simulated import start_simulator
    from sphere.sim.soak import board_profile_command

    need_board()
    need_firmware()
    extra = ["--board", board] if board else []
    if profile:
        send = board_profile_command(profile, tmp / "set_board.txt")
        assert send is not None, profile
        extra += ["--send", str(send)]
    try:
        return start_simulator(trace, seconds=seconds, extra=extra)
    except SourceError as e:
        pytest.fail(str(e))




def _ask(port_path: str, packet, want=("REPLY",), timeout_s: float = 3.0):
    """Send one command on the pty through DeviceLink (as `sphere calibrate` does); return its REPLY and the
    packets that came with it until ``want`` were all seen."""
    from sphere.link.device import DeviceLink
    from sphere.link.port import open_port

    link = DeviceLink(open_port(port_path, reset_on_open=False))
    seen, reply = [], None
    try:
        seq = link.send(packet)
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            for dp in link.read():
                p = dp.packet
                if p.NAME == "REPLY" and p.cmd_seq == seq and p.cmd_type == packet.TYPE:
                    reply = p
                if reply is not None or p.NAME != "REPLY":
                    seen.append(p)
            if reply is not None and all(any(p.NAME == w for p in seen) for w in want):
                break
    finally:
        link.port.close()
    return reply, seen


def _held(reply):
    from sphere.commands.calibrate import block_of
    from sphere.protocol import CalibrationBlock
    from sphere.protocol.packets import CALIBRATION_STATE_BITS, bit_names

    assert reply is not None and reply.ok and len(reply.data) == CalibrationBlock.SIZE + 1, reply
    return (block_of(CalibrationBlock.unpack(reply.data[:CalibrationBlock.SIZE])),
            set(bit_names(reply.data[-1], CALIBRATION_STATE_BITS)))


def _check_recovered(block):
    q14 = 16384
    gyro = T.CAL_GYRO_BIAS_DPS * chips.ITG3200_LSB_PER_DPS
    assert np.allclose(block["gyro_bias"], gyro, atol=1.0), (block["gyro_bias"], gyro)
    offset = T.CAL_ACCEL_OFFSET_G * chips.ADXL345_LSB_PER_G
    assert np.allclose(block["accel_offset"], offset, atol=1.0), (block["accel_offset"], offset)
    scale = q14 / T.CAL_ACCEL_SCALE  # reading = scale · true + offset → gain = 1 / scale
    assert np.allclose(block["accel_scale"], scale, atol=20), (block["accel_scale"], scale)
    hard = T.CAL_MAG_HARD_IRON_UT * chips.HMC5883L_LSB_PER_UT
    assert np.allclose(block["mag_offset"], hard, atol=2.0), (block["mag_offset"], hard)
    W = np.array(block["mag_soft_iron"], float).reshape(3, 3) / q14 @ T.CAL_MAG_SOFT_IRON
    assert np.allclose(W / np.cbrt(np.linalg.det(W)), np.eye(3), atol=0.01), W


def test_guided_calibration_on_the_virtual_sphere(tmp_path, capsys, monkeypatch):
    """A GY-85 with its profile set: the axis check passes, the calibration is recovered in the body frame."""
    from sphere.cli import main
    from sphere.protocol import GetCalibration, Reboot
    from sphere.protocol.packets import REBOOT_MAGIC

    out, cap = tmp_path / "cal.json", tmp_path / "session.cap"
    proc, pty = _start("synthetic:calibration", CAL_SIM_S, "gy85", "gy85", tmp_path, monkeypatch)
    try:
        t0 = time.monotonic()
        rc = main(["calibrate", "--port", pty, "--yes", "--timeout", str(TIMEOUT_S), "--json", str(out),
                   "--save-capture", str(cap)])
        took = time.monotonic() - t0
        err = capsys.readouterr().err
        assert rc == 0, err
        for step in ("1/4 gyro bias", "2/4 axis check", "axes agree", "(board profile gy85)", "3/4 accelerometer",
                     "4/4 magnetometer", "+x up seen", "−z up (upside down) seen",
                     "sent to the sphere", "saved to EEPROM", "read back: the sphere holds it"):
            assert step in err, (step, err)
        block = {k: tuple(v) for k, v in json.loads(out.read_text())["block"].items()}
        _check_recovered(block)
        # the device holds exactly that block, saved: read it back ourselves, then after a reboot from EEPROM
        held, state = _held(_ask(pty, GetCalibration())[0])
        assert held == block
        assert {"gyro_bias_valid", "accel_calibrated", "mag_calibrated", "from_eeprom"} <= state, state
        reply, seen = _ask(pty, Reboot(magic=REBOOT_MAGIC), want=("REPLY", "HELLO"), timeout_s=5.0)
        assert reply is not None and reply.ok
        hello = [p for p in seen if p.NAME == "HELLO"]
        assert hello and hello[-1].calibration_state & 0b1111 == 0b1111, hello  # loaded from EEPROM at start
        held, state = _held(_ask(pty, GetCalibration())[0])
        assert held == block and "from_eeprom" in state and "eeprom_invalid" not in state, (held, state)
    finally:
        stop_simulator(proc)
    print(f"guided session on the virtual sphere: {took:.1f} s wall")
    # the session's bytes, kept with --save-capture, give the same result offline (same detection)
    assert main(["calibrate", "--capture", str(cap), "--json", str(tmp_path / "offline.json")]) == 0
    offline = json.loads((tmp_path / "offline.json").read_text())["block"]
    _check_recovered(offline)
    assert "axes agree" in (err := capsys.readouterr().err) and "(board profile gy85)" in err, err  # its HELLO


def test_a_face_that_never_comes_times_out_and_sends_nothing(tmp_path, capsys):
    """`synthetic:still` lies z up: the gyro step passes, the accelerometer step never sees the other
    five faces; with a short --timeout the session stops, says which faces are missing, sends nothing.
    (--no-axis-check: a still sphere never turns.)"""
    from sphere.cli import main
    from sphere.protocol import GetCalibration

    out = tmp_path / "cal.json"
    proc, pty = _start("synthetic:still", 60)
    try:
        # 15 s: the gyro step needs 3 simulated s, and the board may run at 0.7 simulated s per wall s or less
        rc = main(["calibrate", "--port", pty, "--yes", "--timeout", "15", "--json", str(out), "--no-axis-check"])
        err = capsys.readouterr().err
        assert rc == 1, err
        assert "+z up (upright) seen (1/6)" in err, err
        assert "2/4 axis check: skipped (--no-axis-check)" in err, err
        assert ("step 3/4 (accelerometer) timed out after 15 s: faces not seen: +x up, −x up, +y up, −y up, "
                "−z up (upside down)") in err, err
        assert "Nothing was sent" in err and "SET_CALIBRATION block" not in err, err
        assert not out.exists()
        held, state = _held(_ask(pty, GetCalibration())[0])
    finally:
        stop_simulator(proc)
    # the device still has the defaults (its own power-up gyro bias estimate aside): nothing was set or saved
    assert held["accel_offset"] == (0, 0, 0) and held["accel_scale"] == (16384,) * 3, held
    assert held["mag_offset"] == (0, 0, 0) and held["mag_soft_iron"] == (16384, 0, 0, 0, 16384, 0, 0, 0, 16384), held
    assert not state & {"accel_calibrated", "mag_calibrated", "from_eeprom"}, state


#: The mismatches: the board, what the verdict must say of each chip (None: it agrees), and the profile it
#: must suggest. The mountings are hardware/sim/README.md's (chip axis i reads ± body axis k).
WRONG_PROFILE = {
    "sen10724": ({"gyroscope": None, "magnetometer": "turned 90° about −z (its x axis along the body’s −y, y along +x; z "
                  "agrees)"}, "SparkFun 9DoF Sensor Stick"),
    "gy85": ({"gyroscope": "turned 180° about +z (its x axis along the body’s −x, y along −y; z agrees)",
              "magnetometer": "turned 90° about +z (its x axis along the body’s +y, y along −x; z agrees)"}, "GY-85"),
}


@pytest.mark.parametrize("board", sorted(WRONG_PROFILE))
def test_the_axis_check_names_the_chip_a_wrong_profile_mounts_wrongly(tmp_path, capsys, monkeypatch, board):
    """The firmware left at `aligned` on another board: step 2/4 names each chip mounted otherwise, says which
    profile fits and how to set it, and stops before anything is sent."""
    from sphere.cli import main
    from sphere.protocol import GetCalibration

    out = tmp_path / "cal.json"
    proc, pty = _start("synthetic:calibration", AXES_SIM_S, board, None, tmp_path, monkeypatch)
    try:
        rc = main(["calibrate", "--port", pty, "--yes", "--timeout", "25", "--json", str(out)])
        err = capsys.readouterr().err
        held, state = _held(_ask(pty, GetCalibration())[0])
    finally:
        stop_simulator(proc)
    assert rc == 1, err
    assert "axes disagree with the board profile aligned" in err, err
    chips_said, title = WRONG_PROFILE[board]
    for name, how in chips_said.items():
        assert (f"the {name}: its chip is {how}" in err) if how else (f"the {name}:" not in err), (name, err)
    assert f"the board looks like a {title}" in err and f"`sphere device --port {pty} set board={board}`" in err, err
    assert "Nothing was sent" in err and "3/4 accelerometer" not in err and not out.exists(), err
    assert held["accel_scale"] == (16384,) * 3 and not state & {"accel_calibrated", "mag_calibrated"}, (held, state)
