"""The firmware behind each of the Nano's boot loaders on the virtual board (sphere.sim.restarts; the 100-in-a-row
figures: hardware/sim/bench_restarts.py). A REBOOT, a hung main loop and a host's DTR reset each bring HELLO back
within 2 s, never a reset loop (the old bootloader cannot take a watchdog reset: the firmware restarts itself
instead), with a reset cause that is the event's or 0 (unknown: Optiboot 4.4 clears MCUSR and hands nothing
over), and the gyro bias kept over the DTR reset."""

from __future__ import annotations

import pytest

from simscenarios import need_board, need_firmware
from sphere.sim.restarts import restart_run

EXTERNAL, WATCHDOG = 0x02, 0x08
# what HELLO can know behind each: Optiboot 4.4 leaves MCUSR cleared, so a DTR reset reads "unknown"
DTR_CAUSE = {"none": EXTERNAL, "optiboot4": 0, "optiboot8": EXTERNAL, "atmegaboot": EXTERNAL}
POWER_UP_CAUSE = {"none": 1, "optiboot4": 0, "optiboot8": 1, "atmegaboot": 1}


@pytest.mark.parametrize("loader", ["none", "optiboot4", "optiboot8", "atmegaboot"])
@pytest.mark.parametrize("kind", ["reboot", "hang", "dtr"])
def test_hello_again_within_2_s_with_a_cause_that_is_right_or_unknown(loader, kind):
    need_board()
    r = restart_run(need_firmware(), loader, kind, count=2)
    assert r["within_2s"] == 2, r["events"]
    assert r["wrong_cause"] == 0 and r["extra_hellos"] == 0, r["events"]
    assert r["power_up_cause"] == POWER_UP_CAUSE[loader]
    assert r["causes"] == [WATCHDOG if kind != "dtr" else DTR_CAUSE[loader]], r["events"]
    assert r["bias_kept"] == 2, r["events"]
    if kind != "dtr":
        assert r["board_resets"] == 0  # a restart, not a reset: nothing for a boot loader to get wrong


def test_save_calibration_while_turning_misses_no_period_and_leaves_the_orientation_as_it_was():
    """The EEPROM takes 3.4 ms a byte (the board's model of the ATmega328P); SAVE_CALIBRATION's 45 bytes go a
    byte a period, so at 200 deg/s no period misses its update and the orientation is the run's without the save."""
    need_board()
    from sphere.sim.storage import save_while_turning

    r = save_while_turning(need_firmware(), dps=200)
    assert r["reply_result"] == 0 and 0.2 < r["reply_after_s"] < 0.3, r
    assert r["save"]["eeprom_writes"] == 45 and r["save"]["updates"] == r["reference"]["updates"], r
    assert r["missed_periods"] == 0 and r["save"]["device_loop_overruns"] == 0, r
    assert r["compared"] >= 90 and r["max_diff_deg"] < 1.0, r


def test_a_reflash_over_a_stick_left_in_stream_mode_reads_fresh_samples_at_once():
    """An earlier sketch (the bench sketch here) left the ADXL345 in stream mode with an x offset; the firmware is
    flashed over it while the stick stays powered. Its first read is the newest sample (the board's age of the
    data read), and the offset is gone (x reads about 0 g on a still sphere lying flat)."""
    need_board()
    import tempfile
    from pathlib import Path

    from sphere.protocol.packets import RawSample
    from sphere.sim import trace as T
    from sphere.sim.board import probe_elf, run_board
    from sphere.sim.soak import read_frames

    cmds = [(0.3, "w 53 2c 0c"), (0.35, "w 53 38 9f"), (0.4, "w 53 1e 05"), (0.45, "w 53 2d 08")]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        trace = T.to_chips(T.still(2.0)).write(tmp / "t.bin")
        (tmp / "s.txt").write_text("".join(f"{t:.3f} {(c + chr(10)).encode().hex(' ')}\n" for t, c in cmds))
        r = run_board(need_firmware(), trace, 2.0, tmp / "c.bin", send=tmp / "s.txt", previous=(probe_elf(), 1.0),
                      capture_times=tmp / "t.times")
        frames = read_frames((tmp / "c.bin").read_bytes(), (tmp / "t.times").read_bytes())
    assert [f["kind"] for f in r.stats["faults"]] == ["reflash"]
    (first_age,) = r.stats["adxl345_data_age_ms"]["first_after_start"]
    assert first_age < 5.0, r.stats["adxl345_data_age_ms"]
    assert r.stats["adxl345_data_age_ms"]["max"] < 5.0
    raws = [f.packet for f in frames if f.ok and isinstance(f.packet, RawSample)]
    assert raws and abs(raws[0].accel[0]) < 4 and abs(raws[0].accel[2] - 256) < 8, raws[0]


def test_the_firmware_keeps_the_bus_within_the_sensors_limits():
    """No AVR pull-up beside the sensor board's, no line driven high (also in the bus clear that frees a chip
    holding SDA at power-up), and an SCL low time of at least fast mode's 1.3 us."""
    need_board()
    from sphere.sim import trace as T
    from sphere.sim.board import run_board
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        trace = T.to_chips(T.still(1.0)).write(Path(tmp) / "t.bin")
        r = run_board(need_firmware(), trace, 1.0, sda_held=True)
    bus = r.stats["bus"]
    assert bus["avr_pullup_events"] == 0 and bus["driven_high_events"] == 0 and not bus["over_limit"], bus
    assert bus["scl_low_ok"] and bus["scl_low_us"] >= 1.3 and bus["scl_khz"] == pytest.approx(347.8, abs=0.1), bus
    assert "sda_released" in {f["kind"] for f in r.stats["faults"]}, r.stats["faults"]  # the bus clear freed it
