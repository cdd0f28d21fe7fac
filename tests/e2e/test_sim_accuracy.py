"""The accuracy comparison of `sphere sim --accuracy` (sphere.sim.analysis.accuracy) on a stream made
in Python: ORIENTATION packets that carry BROAD's own optical reference (turned to NWU, Q14) must score
close to zero with the dataset's metric, which checks the time alignment and the frame conversion; the
host Madgwick column runs on RAW_SAMPLE packets made from the same slice as the board's models make them."""

from __future__ import annotations

import numpy as np
import pytest

from sphere import quaternion as quat
from sphere.protocol import Hello, Orientation, RawSample
from sphere.sim import trace as T
from sphere.sim.analysis import CaptureSummary, accuracy, accuracy_table


def _slice():
    from sphere.broad import BroadMissing, find_trial, load_trial

    try:
        trial = load_trial(find_trial("02"))
    except BroadMissing as e:
        pytest.skip(str(e))
    return trial.seconds(38.0, 20.0)


def test_reference_as_firmware_output_scores_near_zero():
    sl = _slice()
    hold = 1.0
    # ORIENTATION at 100 Hz: the reference at the newest BROAD sample, NWU, Q14
    t_o = np.arange(0, hold + 20.0, 0.01)
    idx = np.clip(np.floor((t_o - hold) * sl.rate_hz).astype(int), 0, len(sl) - 1)
    q_ref = sl.opt_quat.copy()
    ok = np.all(np.isfinite(q_ref), axis=1)
    q_ref[~ok] = q_ref[np.argmax(ok)]
    q_nwu = quat.multiply(quat.conjugate(quat.Q_NWU_TO_ENU), q_ref[idx])
    # flags as the firmware sets them: mag_used, and `converging` (start-up gain) for the first 400
    # samples, which the host filter follows (it starts at the identity, as the firmware does)
    ori = [Orientation(t_us=int(round(t * 1e6)), flags=1 | (8 if t < 2.0 else 0),
                       quat=[int(round(v * 16384)) for v in q]) for t, q in zip(t_o, q_nwu)]
    # RAW_SAMPLE at 200 Hz from the board's conversion of the same slice (after a still lead-in)
    ct = T.to_chips(T.hold_first(T.from_broad(sl), hold))
    n = min(len(ct.accel_lsb), len(ct.gyro_lsb))
    mag_idx = np.minimum((np.arange(n) / 200.0 * ct.mag_rate_hz).astype(int), len(ct.mag_lsb) - 1)
    raw = [RawSample(t_us=int(i * 5000), flags=7, accel=list(map(int, ct.accel_lsb[i])),
                     gyro=list(map(int, ct.gyro_lsb[i])), mag=list(map(int, ct.mag_lsb[mag_idx[i]])))
           for i in range(n)]
    hello = Hello(protocol_version=1, firmware_version=[0, 0, 0], sensors_found=7, adxl345_devid=0xE5,
                  itg3200_whoami=0x68, hmc5883l_id=[72, 52, 51], imu_rate_hz=200, mag_rate_hz=75,
                  stream_mode=3, raw_rate_hz=200, orientation_rate_hz=100, calibration_state=0)
    summary = CaptureSummary(hello=hello, hellos=1, raw=raw, orientation=ori)
    row = accuracy(summary, sl, hold, beta=0.041, bias_s=1.0)
    assert row.firmware is not None, row.note
    assert row.firmware["total"] < 0.75, row.firmware  # 0.48: the 10 ms hold of a 100 Hz stream
    print(accuracy_table([row]))
    table = accuracy_table([row])
    assert sl.name in table
    try:
        import sphere.fusion.madgwick  # noqa: F401
    except ImportError:
        assert row.host is None
        return
    assert row.host is not None and row.host["total"] < 10.0, row.host
    assert row.fw_vs_host_rms_deg is not None


def test_firmware_startup_bias_replays_the_devices_windows():
    """The host's replay of the firmware's power-up bias estimate: a window that moves is dropped at the
    moving reading, the next starts after it, the mean is rounded half away from zero, and it applies
    from the window's last reading; ten moving windows give none."""
    from sphere.sim.analysis import STARTUP_BIAS_SAMPLES as N, firmware_startup_bias

    def raw(gyros):
        return [RawSample(t_us=5000 * i, flags=7, accel=[0, 0, 256], gyro=list(g), mag=[100, 0, -300])
                for i, g in enumerate(gyros)]

    still = [(10, -3, 0)] * (N - 1) + [(11, -4, 1)]  # sums 2001, -601, 1 → 10.005, -3.005, 0.005
    assert firmware_startup_bias(raw(still)) == (N - 1, [10, -3, 0])
    # a 30 LSB jump (> 29) at reading 50 ends the first window; the second starts at 51
    moved = [(0, 0, 0)] * 50 + [(30, 0, 0)] + [(-7, 2, 5)] * N
    assert firmware_startup_bias(raw(moved)) == (51 + N - 1, [-7, 2, 5])
    # half away from zero: -7.5 → -8
    half = [(-7, 0, 0)] * (N // 2) + [(-8, 0, 0)] * (N // 2)
    assert firmware_startup_bias(raw(half))[1] == [-8, 0, 0]
    always_moving = [((i % 2) * 100, 0, 0) for i in range(12 * N)]
    assert firmware_startup_bias(raw(always_moving)) is None


def test_firmware_bias_schedule_follows_the_tracking_windows():
    """The host's replay of the firmware's bias tracking (SphereDevice::trackBias, the same numbers as the
    native test "gyro bias is tracked whenever the sphere is still"): after the power-up estimate, every
    still window of TRACK_SAMPLES moves the bias by at most TRACK_STEP_LSB towards its mean; stale gyro
    readings are skipped; a moving reading restarts the window after it."""
    from sphere.sim.analysis import STARTUP_BIAS_SAMPLES as N, TRACK_SAMPLES as W, TRACK_STEP_LSB as S
    from sphere.sim.analysis import firmware_bias_schedule

    def raw(gyros, flags=7):
        return [RawSample(t_us=5000 * i, flags=flags, accel=[0, 0, 256], gyro=list(g), mag=[100, 0, -300])
                for i, g in enumerate(gyros)]

    r = raw([(5, -7, 1)] * N + [(11, -7, 1)] * (4 * W))
    sched = firmware_bias_schedule(r)
    assert sched[0] == (N - 1, [5, -7, 1])
    assert [b for _, b in sched[1:]] == [[5 + S, -7, 1], [5 + 2 * S, -7, 1], [11, -7, 1], [11, -7, 1]]
    assert [k for k, _ in sched[1:]] == [N + W * (j + 1) - 1 for j in range(4)]
    # a gyro_stale reading is not part of a window; a moving one restarts it
    r = raw([(5, -7, 1)] * N) + raw([(8, -7, 1)] * 10, flags=7 | 0x40) + raw([(5, -7, 1)] * 5 + [(60, 0, 0)]
                                                                            + [(5, -7, 1)] * W)
    sched = firmware_bias_schedule(r)
    assert len(sched) == 2 and sched[1][0] == len(r) - 1


def test_stillness_takes_a_noisy_field_and_sees_a_slow_turn_in_the_halves_means():
    """The host's replay of the firmware's stillness test (gyro_bias.cpp, the same numbers as the native
    test "a still window with a noisy field is accepted"): magnetometer readings may scatter by ±15 LSB
    (a module's noise), but a 3 °/s turn about the vertical, each reading within the per-reading span,
    moves the second half's mean from the first's and ends the window at its last reading; readings without
    a magnetometer do not count in the means."""
    from sphere.sim.analysis import TRACK_SAMPLES as W, _moved_at

    rng = np.random.default_rng(1)
    noisy = [RawSample(t_us=5000 * i, flags=7, accel=[0, 0, 256], gyro=[7, -3, -4],
                       mag=[300 + int(rng.integers(-15, 16)), int(rng.integers(-15, 16)), -400]) for i in range(W)]
    assert _moved_at(noisy, range(W)) is None
    # readings without a magnetometer (a glitch in the second half) are left out of the means
    glitch = [RawSample(t_us=p.t_us, flags=3, accel=p.accel, gyro=p.gyro, mag=[0, 0, 0]) if 300 <= i < 320 else p
              for i, p in enumerate(noisy)]
    assert _moved_at(glitch, range(W)) is None
    h = np.radians(3.0 * np.arange(W) / 200.0)
    turn = [RawSample(t_us=5000 * i, flags=7, accel=[0, 0, 256], gyro=[7, -3, -4],
                      mag=[int(round(300 * np.cos(a))), int(round(-300 * np.sin(a))), -400]) for i, a in enumerate(h)]
    assert _moved_at(turn, range(W)) == W - 1


def test_the_host_reference_predicts_its_output_as_the_firmware_does():
    """ORIENTATION carries the state GYRO_DELAY_S ahead at the update's rate (SphereDevice::orientationQ14);
    the host reference following the firmware does the same to its output: at a steady 100 °/s about z its
    outputs lead the plain filter's by 100 °/s · GYRO_DELAY_S."""
    from sphere.sim.analysis import GYRO_DELAY_S, host_madgwick

    rate_lsb = 1438  # 100 °/s
    raw = [RawSample(t_us=5000 * i, flags=7, accel=[0, 0, 256], gyro=[0, 0, rate_lsb], mag=[300, 0, -400])
           for i in range(200)]
    ori = [Orientation(t_us=5000 * i, flags=0x01, quat=[16384, 0, 0, 0]) for i in range(0, 200, 2)]
    follow = host_madgwick(raw, 200, 0.0, 0.0, orientation=ori)
    plain = host_madgwick(raw, 200, 0.0, 0.0)  # not following: no prediction (starts at the e-compass: level, north)
    if follow is None:
        pytest.skip("sphere.fusion.madgwick missing [optional]")
    yaw = lambda q: np.degrees(2 * np.arctan2(q[:, 3], q[:, 0]))  # noqa: E731
    lead = yaw(follow[1])[-1] - yaw(plain[1])[-1]
    assert lead == pytest.approx(rate_lsb / 14.375 * GYRO_DELAY_S, rel=0.02)
