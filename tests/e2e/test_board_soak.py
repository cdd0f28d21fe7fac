"""The soak run (`sphere sim --soak`): its checks on hand-made byte streams whose faults are known, and one
short soak of the firmware image end to end (the report's shape and its verdict agreeing with the exit
status; whether today's firmware passes is the firmware's business, not this test's)."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from sphere.protocol import encode_frame
from sphere.protocol.packets import ORI_CONVERGING, Hello, Orientation, RawSample
from sphere.sim import soak as S


def _hello():
    return Hello(protocol_version=2, firmware_version=(1, 0, 0), sensors_found=7, adxl345_devid=0xE5,
                 itg3200_whoami=0x68, hmc5883l_id=(72, 52, 51), imu_rate_hz=200, mag_rate_hz=75, stream_mode=3,
                 raw_rate_hz=200, orientation_rate_hz=100, calibration_state=0)


def _raw(t_us, flags=0x0F):
    return RawSample(t_us=t_us, flags=flags, accel=(0, 0, 256), gyro=(0, 0, 0), mag=(0, 218, -490))


def _stream(items):
    """items: (simulated s, packet, seq) or (simulated s, raw bytes) -> (capture, --capture-times records)."""
    cap, times = bytearray(), bytearray()
    for it in items:
        cap += encode_frame(it[1], it[2]) if len(it) == 3 else it[1]
        times += struct.pack("<Qd", len(cap), it[0])
    return bytes(cap), bytes(times)


def _need_broad() -> None:
    from sphere.broad import BroadMissing, trial_paths

    try:
        if not trial_paths():
            pytest.fail("no BROAD trials")
    except BroadMissing as e:
        pytest.fail(str(e))


def _need_soak():
    """The board, the firmware image and BROAD's trials (the soak's motion): the image's path."""
    from simscenarios import need_board, need_firmware

    need_board()
    elf = need_firmware()
    _need_broad()
    return elf


def test_frames_are_placed_in_simulated_time_and_bad_ones_kept():
    cap, times = _stream([(0.1, _hello(), 0), (0.105, _raw(5000), 1), (0.11, b"\x05\x01\x02\x03\x04\x00"),
                          (0.115, _raw(15000), 2)])
    f = S.read_frames(cap, times)
    assert [x.ok for x in f] == [True, True, False, True]
    assert [x.t_s for x in f] == [0.1, 0.105, 0.11, 0.115]
    assert isinstance(f[1].packet, RawSample) and f[1].seq == 1


def test_a_resent_frame_and_time_going_back_are_stale_a_gap_is_dropped_frames():
    items = [(0.0, _hello(), 0)] + [(0.005 * i, _raw(5000 * i), i) for i in range(1, 6)]
    items += [(0.030, _raw(5000 * 3), 3)]  # the transmit buffer sent again: an old frame
    items += [(0.035, _raw(5000 * 9), 9)]  # three frames missing
    s = S.stream_checks(S.read_frames(*_stream(items)), [])
    assert s["stale_frames"].count == 1 and s["stale_frames"].first_s == 0.03
    assert s["frames_dropped"].count == 3
    # the same sequence number with the time moving on (the host missed 256 frames): not stale
    items = [(0.0, _hello(), 0), (0.005, _raw(5000), 1), (1.3, _raw(5000 + 257 * 5000), 2)]
    assert S.stream_checks(S.read_frames(*_stream(items)), [])["stale_frames"].count == 0
    # exactly 256 frames lost (a host stall, seed 106): the same sequence number again, the device's time 850 ms on
    items = [(0.0, _hello(), 0), (46.97083, _raw(5219728), 218), (47.82082, _raw(6069728), 218)]
    s = S.stream_checks(S.read_frames(*_stream(items)), [])
    assert s["stale_frames"].count == 0 and s["frames_dropped"].count == 255
    # the same sequence number and the same device time: the frame sent twice
    items = [(0.0, _hello(), 0), (0.005, _raw(5000), 1), (0.010, _raw(5000), 1)]
    assert S.stream_checks(S.read_frames(*_stream(items)), [])["stale_frames"].count == 1
    # a HELLO starts the sequence and the clock again: not stale
    items = [(0.0, _hello(), 0), (0.005, _raw(5000), 1), (0.5, _hello(), 0), (0.505, _raw(5000), 1)]
    s = S.stream_checks(S.read_frames(*_stream(items)), [])
    assert s["stale_frames"].count == 0 and s["hellos"] == 2
    # the device's time starting again after an injected reset whose HELLO the host never got: a restart
    items = [(0.0, _hello(), 0), (1.0, _raw(1000000), 1), (1.3, _raw(200000), 7)]
    s = S.stream_checks(S.read_frames(*_stream(items)), [], resets_t=[1.1])
    assert s["stale_frames"].count == 0 and s["hellos_lost"] == 1
    assert S.stream_checks(S.read_frames(*_stream(items)), [])["stale_frames"].count == 1


def test_crc_errors_count_only_outside_injected_line_faults():
    bad = b"\x03\x11\x22\x00"
    items = [(0.0, _hello(), 0), (0.2, bad), (0.5, bad)]
    s = S.stream_checks(S.read_frames(*_stream(items)), [(0.15, 0.25)])
    assert s["crc_errors"].count == 1 and s["crc_errors"].first_s == 0.5


def test_recovery_waits_for_ok_and_not_stale_and_fresh_magnetometer_data():
    items = [(0.0, _hello(), 0), (1.000, _raw(1000000, 0x01), 1), (1.005, _raw(1005000, 0x03 | 0x40), 2),
             (1.010, _raw(1010000, 0x07), 3), (1.015, _raw(1015000, 0x0F), 4)]
    frames = S.read_frames(*_stream(items))
    ends = [{"kind": "nack", "t_start": 0.9, "t_end": 0.999, "chips": ["itg3200", "hmc5883l"]}]
    worst, rows = S.recovery(frames, ends)
    got = {r["chip"]: r["recovery_ms"] for r in rows}
    assert got == {"itg3200": pytest.approx(11.0), "hmc5883l": pytest.approx(16.0)}
    assert worst.count == pytest.approx(16.0) and worst.first_s is None  # within the 100 ms limit
    # a fault ending while the host did not read: counted from the end of that stall
    _, rows = S.recovery(frames, ends, host_stalls=[(0.5, 1.004)])
    assert {r["chip"]: r["recovery_ms"] for r in rows} == {"itg3200": pytest.approx(6.0), "hmc5883l": pytest.approx(11.0)}


def test_orientation_excess_against_the_reference_two_seconds_after_a_fault():
    def q(t, quat, seq):
        return (t, Orientation(t_us=int(t * 1e6), flags=0, quat=quat), seq)
    one = (16384, 0, 0, 0)
    turned = (16135, 0, 0, 2845)  # 20 deg about z, Q14
    dev = [(0.0, _hello(), 0), q(3.0, turned, 1)]
    ref = [(0.0, _hello(), 0), q(3.0, one, 1)]
    ends = [{"kind": "nack", "t_start": 0.9, "t_end": 1.0, "chips": ["itg3200"]}]
    worst, rows = S.orientation_excess(S.read_frames(*_stream(dev)), S.read_frames(*_stream(ref)), ends, [])
    assert rows[0]["excess_deg"] == pytest.approx(20.0, abs=0.1) and worst.first_s == 3.0


def test_schedule_is_seeded_and_has_every_kind():
    a, b = S.schedule(60, 5), S.schedule(60, 5)
    assert a == b and a != S.schedule(60, 6)
    assert {"nack", "stall", "brownout", "reset_mid_read", "host_stall", "glitch", "sda_held"} <= set(a)


def test_a_short_soak_of_the_firmware(tmp_path, capsys):
    """`sphere sim --soak`: one summary line, a JSON report with every invariant's count and first time, and
    exit 1 exactly when the report lists a failed invariant."""
    from sphere.cli import main

    elf = _need_soak()
    out = tmp_path / "soak.json"
    rc = main(["sim", "--soak", "14", "--seed", "2", "--firmware", str(elf), "--json", str(out)])
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sphere sim --soak 14 s seed 2 board aligned:"), lines
    r = json.loads(out.read_text())
    for k in ("stale_frames", "crc_errors", "sensor_recovery_ms", "orientation_excess_deg", "frames_dropped"):
        assert {"count", "first_s"} <= set(r["invariants"][k])
    assert {"resets", "overruns"} <= set(r["invariants"])
    assert rc == (1 if r["failed"] else 0)
    kinds = {f["kind"] for f in r["faults"]}
    assert "sda_held_at_power_up" in kinds and ({"nack_start", "stall_start", "brownout", "reset_mid_read",
                                                 "host_stall"} & kinds)
    assert r["recoveries"] and r["speed"] > 0


def test_a_frame_cut_by_a_reset_is_injected_until_the_rebooted_firmware_speaks():
    """A reset mid-frame (here during a host stall, with the bus held after it): the cut frame is judged only
    when the rebooted firmware's first delimiter arrives, 300 ms later and 100 ms after the host reads again; it
    is the injected fault, not a CRC error. A damaged frame after the firmware is heard again counts."""
    bad = b"\x03\x11\x22\x00"
    items = [(0.0, _hello(), 0), (1.0, _raw(1000000), 1), (1.30, bad), (1.31, _hello(), 0), (1.5, bad)]
    frames = S.read_frames(*_stream(items))
    log = [{"t": 0.9, "kind": "host_stall"}, {"t": 1.0, "kind": "reset_mid_read"}, {"t": 1.2, "kind": "host_reads"}]
    line, stalls = S.line_fault_windows(log, frames)
    assert stalls == [(0.9, 1.2)]
    s = S.stream_checks(frames, line, [1.0])
    assert s["crc_errors"].count == 1 and s["crc_errors"].first_s == 1.5


def test_an_orientation_check_while_the_host_does_not_read_waits_for_it():
    """2 s after a fault the host is in a stall: nothing the device sends reaches it, so the check is made at the
    first ORIENTATION after the stall, not reported as 'no orientation'."""
    def q(t, quat, seq):
        return (t, Orientation(t_us=int(t * 1e6), flags=0, quat=quat), seq)
    one = (16384, 0, 0, 0)
    dev = [(0.0, _hello(), 0), q(1.9, one, 1), q(3.55, one, 2)]
    ref = [(0.0, _hello(), 0)] + [q(1.9 + 0.05 * i, one, i + 1) for i in range(40)]
    ends = [{"kind": "nack", "t_start": 0.9, "t_end": 1.0, "chips": ["itg3200"]}]
    a, b = S.read_frames(*_stream(dev)), S.read_frames(*_stream(ref))
    worst, rows = S.orientation_excess(a, b, ends, [])
    assert rows[0]["excess_deg"] is None or rows[0]["excess_deg"] == float("inf")  # without the stall: none there
    worst, rows = S.orientation_excess(a, b, ends, [], host_stalls=[(2.5, 3.5)])
    assert rows[0]["t"] == pytest.approx(3.55) and rows[0]["excess_deg"] == pytest.approx(0.0, abs=1e-6)
    assert worst.first_s is None


def _turning(t0, t1, rate_dps, phase_s=0.0, flags=0, offset_deg=0.0):
    """ORIENTATIONs at 100 Hz of a sphere turning about z at ``rate_dps`` (the quaternion of the true
    orientation at each sample's time), sampled ``phase_s`` after the 10 ms grid, turned by ``offset_deg``."""
    import math
    items, seq, t = [(0.0, _hello(), 0)], 1, t0 + phase_s
    while t < t1:
        half = math.radians(rate_dps * t + offset_deg) / 2
        quat = (round(16384 * math.cos(half)), 0, 0, round(16384 * math.sin(half)))
        items.append((t, Orientation(t_us=int(t * 1e6), flags=flags, quat=quat), seq & 0xFF))
        seq, t = seq + 1, t + 0.01
    return S.read_frames(*_stream(items))


def test_both_runs_are_compared_at_the_same_instant():
    """The two runs' ORIENTATIONs come 5 ms apart in phase (after a reset the faulty run boots later, e.g. a chip
    held SDA) while both follow the same fast turn exactly (500 °/s). Taking each run's first sample at or after
    the check time (the rule before) compares instants 5 ms apart: 2.5°, a false alarm over the 2° limit. Both
    are taken at the check's instant now: no difference. A real difference still counts."""
    ends = [{"kind": "clock_stretch", "t_start": 1.0, "t_end": 1.0, "chips": ["itg3200"]}]
    dev, ref = _turning(0.5, 3.5, 500.0, phase_s=0.005), _turning(0.5, 3.5, 500.0)
    ta, qa, _ = S._quats(dev)
    tb, qb, _ = S._quats(ref)
    ia, ib = np.searchsorted(ta, 3.0), np.searchsorted(tb, 3.0)
    assert S._angle_deg(qa[ia] / np.linalg.norm(qa[ia]), qb[ib] / np.linalg.norm(qb[ib])) > 2.0  # the rule before
    worst, rows = S.orientation_excess(dev, ref, ends, [])
    assert rows[0]["excess_deg"] < 0.1 and worst.first_s is None, rows
    a, b = _turning(0.5, 1.05, 500.0, 0.005), _turning(1.05, 3.5, 500.0, 0.005, offset_deg=3.0)  # turned 3° by it
    worst, rows = S.orientation_excess(a + [f for f in b if f.type_ != 0x01], ref, ends, [])
    assert rows[0]["excess_deg"] == pytest.approx(3.0, abs=0.1) and worst.first_s == 3.0


def test_an_orientation_check_in_a_start_up_is_not_judged():
    """After a reset the firmware converges with its start-up gain until it has used 2 s of accelerometer samples,
    saying so in ORIENTATION's `converging` flag; in a fast turn the accelerometer is rejected most of the time
    and that lasts 4-6 s (the first 100 s of the soak at seed 1 with the image of ad128df: its 6 checks over 2°
    all fell 3-6 s after a reset in BROAD's fast turns with both runs converging, up to 3.2° apart before the
    fault they were blamed for). Two start-ups are compared then, not the fault's doing: such a check is listed
    as skipped. The same fault's doing without the flag, 2.5 s or more after the reset, counts."""
    ends = [{"kind": "glitch_nack", "t_start": 1.0, "t_end": 1.0, "chips": ["itg3200"]}]
    ref = _turning(0.5, 3.5, 100.0)
    for dev, r in ((_turning(0.5, 3.5, 100.0, flags=ORI_CONVERGING, offset_deg=10.0), ref),
                   (_turning(0.5, 3.5, 100.0, offset_deg=10.0), _turning(0.5, 3.5, 100.0, flags=ORI_CONVERGING))):
        worst, rows = S.orientation_excess(dev, r, ends, [])
        assert rows[0]["excess_deg"] is None and rows[0]["skipped"].startswith("converging") and worst.first_s is None
    a, b = _turning(0.5, 1.05, 100.0), _turning(1.05, 3.5, 100.0, offset_deg=10.0)  # turned 10° by the fault
    worst, rows = S.orientation_excess(a + [f for f in b if f.type_ != 0x01], ref, ends, [])
    assert rows[0]["excess_deg"] == pytest.approx(10.0, abs=0.1) and worst.first_s == 3.0


def test_start_ups_say_how_long_the_firmware_converged_after_each_reset():
    """Beside the skipped checks: from power-up and each reset to the first ORIENTATION without `converging`; a
    start-up the next reset cuts short has no length (it never ended)."""
    def q(t, flags, seq):
        return (t, Orientation(t_us=int(t * 1e6), flags=flags, quat=(16384, 0, 0, 0)), seq)
    items = [(0.0, _hello(), 0), q(0.5, ORI_CONVERGING, 1), q(2.7, 0, 2), q(5.2, ORI_CONVERGING, 3), q(8.0, ORI_CONVERGING, 4),
             q(9.5, ORI_CONVERGING, 5), q(13.1, 0, 6)]
    ups = S.start_ups(S.read_frames(*_stream(items)), [5.0, 9.0])
    assert ups == [{"t": 0.0, "seconds": 2.7}, {"t": 5.0, "seconds": None}, {"t": 9.0, "seconds": 4.1}]


def test_a_difference_that_was_there_before_the_fault_is_not_its_doing():
    """After a reset the two runs can leave their start-ups a few degrees apart and stay so (the reference is
    not fault-free: it has the same resets). A fault that moves nothing then still reads that difference 2 s
    after it: the rule before blamed it (5° > 2°). A check fails when the device is over the limit off the
    reference AND the fault moved it that far against the reference (from its start to the check), so the
    5° offset is not a fault's doing while 3° added to it is, and so is 20° from nothing."""
    ends = [{"kind": "glitch_nack", "t_start": 1.0, "t_end": 1.0, "chips": ["itg3200"]}]
    ref = _turning(0.5, 3.5, 100.0)
    worst, rows = S.orientation_excess(_turning(0.5, 3.5, 100.0, offset_deg=5.0), ref, ends, [])
    assert rows[0]["diff_deg"] == pytest.approx(5.0, abs=0.1)  # what the rule before judged: over the 2° limit
    assert rows[0]["before_deg"] == pytest.approx(5.0, abs=0.1) and rows[0]["moved_deg"] < 0.1
    assert rows[0]["excess_deg"] < 0.1 and worst.first_s is None
    # the fault adds 3° about the same axis (the device's estimate jumps 50 ms after its start)
    a, b = _turning(0.5, 1.05, 100.0, offset_deg=5.0), _turning(1.05, 3.5, 100.0, offset_deg=8.0)
    dev = a + [f for f in b if f.type_ != 0x01]
    worst, rows = S.orientation_excess(dev, ref, ends, [])
    assert rows[0]["moved_deg"] == pytest.approx(3.0, abs=0.1) and rows[0]["excess_deg"] == pytest.approx(3.0, abs=0.1)
    assert worst.first_s == 3.0


def test_a_fault_while_the_host_does_not_read_is_measured_from_the_last_it_saw():
    """A glitch during a host stall (seed 104, sen10724: 68.94 s in a stall of 68.88-70.21 s, the runs 5.4° apart
    since their start-ups after a reset at 64.03 s): the device's ORIENTATION at the fault's start never reached the
    host, so the difference before it was unknown and the whole 5.7° two seconds later was blamed on the glitch.
    It is measured from the last ORIENTATION the host got before the fault now (a stall does nothing to the
    device): the offset that was there before is not the glitch's doing, 3° added to it still is."""
    ends = [{"kind": "glitch_nack", "t_start": 1.5, "t_end": 1.5, "chips": ["adxl345"]}]
    ref = _turning(0.5, 4.0, 100.0)
    stalls = [(1.2, 2.0)]

    def device(offset_after):
        a, b = _turning(0.5, 1.2, 100.0, offset_deg=5.0), _turning(2.0, 4.0, 100.0, offset_deg=offset_after)
        return a + [f for f in b if f.type_ != 0x01]
    worst, rows = S.orientation_excess(device(5.0), ref, ends, [], host_stalls=stalls)
    assert rows[0]["before_deg"] == pytest.approx(5.0, abs=0.1) and rows[0]["diff_deg"] == pytest.approx(5.0, abs=0.1)
    assert rows[0]["excess_deg"] < 0.1 and worst.first_s is None
    worst, rows = S.orientation_excess(device(8.0), ref, ends, [], host_stalls=stalls)
    assert rows[0]["excess_deg"] == pytest.approx(3.0, abs=0.1) and worst.first_s == 3.5


def test_a_fault_at_the_end_of_the_run_is_not_judged():
    """A magnetometer glitch 0.2 ms before the run ends (seed 209 at 119.9998 s): no RAW_SAMPLE comes after it, so
    its recovery cannot be judged (it was 'never', failing the soak on every board); a fault whose allowance ends
    inside the run and has no fresh sample still fails."""
    items = [(0.0, _hello(), 0)] + [(1.0 + 0.005 * i, _raw(1000000 + 5000 * i, 0x0F), i + 1) for i in range(200)]
    frames = S.read_frames(*_stream(items))
    end = [{"kind": "glitch_nack", "t_start": 1.9998, "t_end": 1.9998, "chips": ["hmc5883l"]}]
    worst, rows = S.recovery(frames, end)
    assert worst.first_s is None and rows[0]["skipped"] == "the run ended first"
    stale = [(0.0, _hello(), 0)] + [(1.0 + 0.005 * i, _raw(1000000 + 5000 * i, 0x03), i + 1) for i in range(200)]
    worst, rows = S.recovery(S.read_frames(*_stream(stale)), [{**end[0], "t_start": 1.5, "t_end": 1.5}])
    assert worst.first_s == 1.5 and "skipped" not in rows[0]


def test_a_fault_that_a_reset_overtakes_is_judged_as_the_reset():
    """A clock stretch (100 ms limit) at the instant of a brown-out: the firmware restarts, so the
    magnetometer's fresh data waits for its start-up, which the reset's own row judges (1000 ms limit); the
    stretch is not judged against 100 ms (a QMC board failed at 260.5 ms this way)."""
    items = [(0.0, _hello(), 0), (1.000, _raw(1000000, 0x03), 1), (1.200, _hello(), 0),
             (1.261, _raw(61000, 0x0F), 1)]
    frames = S.read_frames(*_stream(items))
    ends = [{"kind": "clock_stretch", "t_start": 0.999, "t_end": 0.999, "chips": ["adxl345", "itg3200", "hmc5883l"]},
            {"kind": "brownout", "t_start": 0.9995, "t_end": 0.9995, "chips": ["adxl345", "itg3200", "hmc5883l"]}]
    worst, rows = S.recovery(frames, ends)
    assert worst.first_s is None, rows  # within the reset's 1000 ms
    judged = [r for r in rows if r["kind"] == "clock_stretch"]
    assert all(r.get("overtaken_by") == "brownout" for r in judged), judged
    # the same stretch with no reset near it is judged against 100 ms, and fails
    worst, _ = S.recovery(frames, ends[:1])
    assert worst.first_s == pytest.approx(0.999)


def test_the_seed_by_board_matrix_prints_a_table_and_fails_when_a_run_does(tmp_path):
    """hardware/sim/soak_matrix.py, as its user runs it: one seed on one board, a short soak; a line per run, a
    table row per seed with the verdict, the count of runs that passed, a JSON report per run; the exit status 1
    exactly when a run failed. Seeds it cannot read are refused with one line and exit 2."""
    import subprocess
    import sys
    from pathlib import Path

    elf = _need_soak()
    script = Path(__file__).resolve().parents[2] / "hardware" / "sim" / "soak_matrix.py"
    out = tmp_path / "m.json"
    r = subprocess.run([sys.executable, str(script), "--seeds", "2", "--board", "aligned", "--seconds", "14",
                        "--jobs", "1", "--firmware", str(elf), "--json", str(out)], capture_output=True, text=True,
                       timeout=600)
    lines = r.stdout.strip().splitlines()
    assert lines[0].startswith("sphere sim --soak 14 s seed 2 board aligned:"), r.stdout + r.stderr
    assert "| seed | aligned |" in lines and any(x.startswith("| 2 | PASS") or x.startswith("| 2 | FAIL") for x in lines)
    reports = json.loads(out.read_text())
    assert [(x["seed"], x["board"]) for x in reports] == [(2, "aligned")]
    failed = bool(reports[0]["report"]["failed"])
    assert lines[-1].startswith(f"{0 if failed else 1} of 1 passed") and r.returncode == (1 if failed else 0)
    for bad in ("5-2", "x", ""):
        r = subprocess.run([sys.executable, str(script), "--seeds", bad], capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and r.stdout == "" and "--seeds" in r.stderr and "Traceback" not in r.stderr


def test_the_reference_resets_as_the_faulty_run_did():
    """The reference's resets are the faulty run's as they came: a reset mid-read asked 1 ms before it came (the
    board resets at the next byte a chip sends: the same one), a brown-out at its time, and the sensor holding SDA
    at power-up in both."""
    log = [{"t": 0.0, "kind": "sda_held_at_power_up", "chip": "hmc5883l"}, {"t": 0.242, "kind": "sda_released"},
           {"t": 6.000271, "kind": "reset_mid_read", "chip": "adxl345"}, {"t": 7.1, "kind": "glitch_nack"},
           {"t": 11.052474, "kind": "brownout", "chip": None}]
    assert S.reference_resets(log) == {"brownout": [11.052474], "reset_mid_read": [5.999271], "sda_held": True}
    assert S.reference_resets([{"t": 7.1, "kind": "glitch_nack"}]) == {}


def test_both_runs_are_the_same_until_the_first_fault(tmp_path):
    """With the resets and the held SDA as they came, the two runs boot at the same cycle and read the chips at the
    same phase: until the first fault other than those, their ORIENTATIONs are the same to the bit. (A reference
    that reset plainly, without the held SDA, read the gyro at another phase: with the chips' clocks off the Nano's
    it read a sample twice or missed one at other instants, and in fast turns the runs drifted up to 3.8 degrees
    apart within 2 s with no fault at all: seed 108 on sen10724, 8 of 94 fault-free windows over 2 degrees.)"""
    elf = _need_soak()
    res = S.run_soak(elf, 14, 2, keep=tmp_path)
    first = min(e["t"] for e in res.report["faults"] if e["kind"] not in ("sda_held_at_power_up", "sda_released"))
    runs = []
    for name in ("faulty", "reference"):
        frames = S.read_frames((tmp_path / f"{name}.cap").read_bytes(), (tmp_path / f"{name}.times").read_bytes())
        runs.append([(f.packet.t_us, f.packet.quat) for f in frames if isinstance(f.packet, Orientation) and f.t_s < first])
    assert len(runs[0]) >= 20 and runs[0] == runs[1][: len(runs[0])], first  # the first glitch comes at 0.5 s


def test_the_check_is_also_made_where_nothing_was_injected():
    """The orientation check's own noise: made from every instant with nothing in the fault log, by the same
    rules, it finds nothing between two runs that agree, and a difference that came with no fault when one
    does (a firmware bug, or two runs reading the chips at different phases); it is reported, not judged."""
    ref = _turning(0.5, 12.0, 100.0)
    same = S.fault_free_checks(_turning(0.5, 12.0, 100.0), ref, [{"t": 8.0, "kind": "glitch_nack"}], [])
    assert same["windows"] > 10 and same["max_deg"] < 0.1 and same["over_limit"] == 0
    a, b = _turning(0.5, 6.0, 100.0), _turning(6.0, 12.0, 100.0, offset_deg=3.0)  # 3 deg at 6 s, nothing logged
    stepped = S.fault_free_checks(a + [f for f in b if f.type_ != 0x01], ref, [], [])
    assert stepped["max_deg"] == pytest.approx(3.0, abs=0.1) and stepped["over_limit"] >= 1
    # nothing is checked from 0.5 s before a logged event to 0.1 s after its check
    near = S.fault_free_checks(a + [f for f in b if f.type_ != 0x01], ref, [{"t": 6.0, "kind": "glitch_nack"}], [])
    assert near["over_limit"] == 0


def _sine_turn(seconds=4.0, rate_hz=1000.0, t_gap=2.0):
    """A body turning about z at 500 deg/s * sin(2 pi 10 (t - t_gap)) from t_gap for one 100 ms cycle, still
    otherwise: across the 50 ms from t_gap the rate starts and ends at 0 but turns the body by
    500 (1 - cos pi) / (20 pi) = 15.9 deg."""
    import math

    from sphere.sim import trace as T
    t = np.arange(int(seconds * rate_hz)) / rate_hz
    wz = np.where((t >= t_gap) & (t < t_gap + 0.1), np.radians(500.0) * np.sin(2 * math.pi * 10 * (t - t_gap)), 0.0)
    gyr = np.stack([np.zeros_like(t), np.zeros_like(t), wz], axis=1)
    acc = np.tile([0.0, 0.0, 9.81], (len(t), 1))
    mag = np.tile([20.0, 0.0, -45.0], (len(t), 1))
    return T.Motion(rate_hz, acc, gyr, mag, "sine")


def test_a_perfect_filter_loses_what_a_gyro_gap_hides():
    """What no filter can know: across a gap in the gyroscope's samples the best guess from the samples on either
    side is the rate going linearly between them; a turn that starts and ends inside the gap is invisible. A
    50 ms gap over one half-cycle of a 10 Hz shake at 500 deg/s hides 15.9 deg; a steady turn hides nothing."""
    m = _sine_turn()
    assert S.unavoidable_deg(m, 2.0, 2.05) == pytest.approx(15.9, abs=0.2)
    assert S.unavoidable_deg(m, 0.5, 0.55) == pytest.approx(0.0, abs=1e-6)
    steady = _sine_turn()
    steady.gyr_rad_s[:, 2] = np.radians(300.0)
    assert S.unavoidable_deg(steady, 1.0, 1.06) == pytest.approx(0.0, abs=1e-3)


def test_in_broad_fast_turns_a_gyro_nack_costs_a_perfect_filter_more_than_the_limit():
    """The soak's motion (BROAD) with a 50 ms gyro NACK (the schedule's longest) and a sample period either side:
    at many instants even a perfect filter ends the gap more than 2 deg from the truth (the shakes of the
    disturbed trials; 21.6 % of instants, up to 24 deg, when measured every 10 ms of the 120 s soak), and in those
    turns the accelerometer is rejected and the magnetometer cannot see a turn about the field: the 2 deg limit
    2 s after such a fault is not physics. The check judges the rest (the firmware's doing beyond it), limit
    unchanged: the next test."""
    _need_broad()
    m, _ = S.soak_motion(120.0)
    lost = np.array([S.unavoidable_deg(m, t - 0.005, t + 0.055) for t in np.arange(3.0, 119.9, 0.05)])
    assert lost.max() > 10.0 and np.mean(lost > S.LIMITS["orientation_excess_deg"]) > 0.05, (lost.max(), np.mean(lost > 2))


def test_a_gyro_gaps_unavoidable_turn_is_not_the_firmwares_doing():
    """A gyro NACK across the hidden half-cycle: the device ends 15.9 deg off the reference and stays so (a perfect
    filter would too); only what it is off beyond that counts against the 2 deg limit, and a device 19.9 deg off
    still fails."""
    m = _sine_turn()
    ends = [{"kind": "nack", "t_start": 2.005, "t_end": 2.045, "chips": ["itg3200"]}]
    ref = _turning(0.5, 4.5, 0.0)
    for off, fails in ((15.9, False), (19.9, True)):
        a, b = _turning(0.5, 2.05, 0.0), _turning(2.05, 4.5, 0.0, offset_deg=off)
        dev = a + [f for f in b if f.type_ != 0x01]
        worst, rows = S.orientation_excess(dev, ref, ends, [])
        assert rows[0]["excess_deg"] == pytest.approx(off, abs=0.1)  # without the motion: all of it
        worst, rows = S.orientation_excess(dev, ref, ends, [], motion=m)
        assert rows[0]["unavoidable_deg"] == pytest.approx(15.9, abs=0.2)
        assert rows[0]["excess_deg"] == pytest.approx(off - 15.9, abs=0.2) and (worst.first_s is not None) == fails
