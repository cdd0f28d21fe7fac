"""Calibration math recovers known synthetic parameters."""

from __future__ import annotations

import numpy as np
import pytest

from sphere.calibration import fit as cal
from sphere import chips


def _rotations(n, rng):
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], 1)


def test_gyro_bias_is_the_still_mean_and_motion_is_refused():
    rng = np.random.default_rng(0)
    bias = np.array([12.0, -30.0, 5.0])
    g = bias + rng.normal(0, 2.0, (2000, 3))
    r = cal.gyro_bias(np.rint(g))
    assert np.allclose(r.bias_lsb, bias, atol=0.3)
    assert np.all(r.noise_lsb < 3.0)
    moving = g + np.outer(np.sin(np.linspace(0, 20, 2000)), [500, 0, 0])
    with pytest.raises(ValueError, match="moved"):
        cal.gyro_bias(moving)


def test_accel_six_position_recovers_offset_and_gain():
    rng = np.random.default_rng(1)
    offset = np.array([7.0, -12.0, 20.0])
    sens = np.array([250.0, 262.0, 245.0])  # LSB per g of each axis
    poses = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1],
                      [0.6, 0.8, 0], [0, -0.6, 0.8]], float)
    means = poses * sens + offset + rng.normal(0, 0.3, poses.shape)
    r = cal.accel_six_position(means)
    assert np.allclose(r.offset_lsb, offset, atol=1.0)
    assert np.allclose(r.gain, chips.ADXL345_LSB_PER_G / sens, rtol=3e-3)
    assert r.residual_lsb < 1.0
    corrected = r.apply(poses[0] * sens + offset)
    assert abs(np.linalg.norm(corrected) - 256.0) < 1.5


def test_accel_needs_every_axis_up_and_down():
    with pytest.raises(ValueError, match="up and once down"):
        cal.accel_six_position(np.array([[256, 0, 0], [0, 256, 0], [0, 0, 256]] * 2, float))


def test_mag_ellipsoid_recovers_hard_and_soft_iron():
    rng = np.random.default_rng(2)
    field = np.array([200.0, 0.0, -450.0])  # an earth field in LSB (gain 1: ~45 µT)
    R = _rotations(3000, rng)
    true_field = R @ field
    soft = np.array([[1.15, 0.08, -0.03], [0.08, 0.92, 0.05], [-0.03, 0.05, 1.02]])
    hard = np.array([-80.0, 35.0, 120.0])
    raw = true_field @ soft.T + hard + rng.normal(0, 2.0, true_field.shape)
    r = cal.mag_ellipsoid(np.rint(raw))
    assert np.allclose(r.hard_iron_lsb, hard, atol=3.0)
    # the recovered W undoes soft iron up to a scale: W·soft ∝ a rotation-free identity (W symmetric)
    Ws = r.soft_iron @ soft
    Ws /= np.cbrt(np.linalg.det(Ws))
    assert np.allclose(Ws, np.eye(3), atol=0.02)
    assert r.residual < 0.01
    assert r.norm_after[1] < 0.2 * r.norm_before[1]
    assert abs(r.radius_lsb - np.linalg.norm(field)) / np.linalg.norm(field) < 0.1


def test_mag_ellipsoid_refuses_a_flat_cloud():
    rng = np.random.default_rng(3)
    t = rng.uniform(0, 2 * np.pi, 500)
    flat = np.stack([300 * np.cos(t), 300 * np.sin(t), np.zeros_like(t)], 1) + rng.normal(0, 1, (500, 3))
    with pytest.raises(ValueError, match="orientations"):
        cal.mag_ellipsoid(flat)


def test_from_capture_finds_still_poses_and_all_three_parts():
    rng = np.random.default_rng(4)
    rate = 100.0
    offset, sens = np.array([5.0, -8.0, 10.0]), np.array([255.0, 258.0, 250.0])
    gbias = np.array([20.0, -15.0, 7.0])
    acc, gyr, mag = [], [], []
    field, hard = np.array([200.0, 0.0, -450.0]), np.array([40.0, -60.0, 15.0])
    for d in np.vstack([np.eye(3), -np.eye(3)]):
        n = 300  # 3 s still
        acc.append(d * sens + offset + rng.normal(0, 1.5, (n, 3)))
        gyr.append(gbias + rng.normal(0, 2.0, (n, 3)))
        mag.append(np.tile(field, (n, 1)) + hard)
        # 2 s of turning between poses
        m = 200
        acc.append(rng.normal(0, 150, (m, 3)))
        gyr.append(rng.normal(0, 3000, (m, 3)))
        mag.append(_rotations(m, rng) @ field + hard)
    acc, gyr, mag = np.vstack(acc), np.vstack(gyr), np.vstack(mag)
    c = cal.from_capture(acc, gyr, mag, rate)
    assert c.gyro is not None and np.allclose(c.gyro.bias_lsb, gbias, atol=0.5)
    assert c.accel is not None and c.accel.poses == 6
    assert np.allclose(c.accel.offset_lsb, offset, atol=1.0)
    assert c.mag is not None and np.allclose(c.mag.hard_iron_lsb, hard, atol=5.0)


def _synthetic_session(rng, rate=100.0):
    offset, sens = np.array([5.0, -8.0, 10.0]), np.array([255.0, 258.0, 250.0])
    gbias = np.array([20.0, -15.0, 7.0])
    field, hard = np.array([200.0, 0.0, -450.0]), np.array([40.0, -60.0, 15.0])
    acc, gyr, mag = [], [], []
    for d in np.vstack([np.eye(3), -np.eye(3)]):
        n, m = 300, 200
        acc.append(d * sens + offset + rng.normal(0, 1.5, (n, 3)))
        gyr.append(gbias + rng.normal(0, 2.0, (n, 3)))
        mag.append(np.tile(field, (n, 1)) + hard + rng.normal(0, 1.0, (n, 3)))
        acc.append(rng.normal(0, 150, (m, 3)))
        gyr.append(rng.normal(0, 3000, (m, 3)))
        mag.append(_rotations(m, rng) @ field + hard)
    return np.vstack(acc), np.vstack(gyr), np.vstack(mag), dict(offset=offset, gbias=gbias, hard=hard)


@pytest.mark.slow
def test_calibrate_command_from_a_capture_file(tmp_path, capsys):
    import json

    from sphere.cli import main
    from sphere.protocol import RawSample, encode_frame

    rng = np.random.default_rng(5)
    acc, gyr, mag, truth = _synthetic_session(rng)
    path = tmp_path / "cal.bin"
    with open(path, "wb") as f:
        for i, (a, g, m) in enumerate(zip(acc, gyr, mag)):
            p = RawSample(t_us=i * 10_000, flags=0b1111, accel=tuple(int(v) for v in np.clip(np.rint(a), -4096, 4095)),
                          gyro=tuple(int(v) for v in np.rint(g)), mag=tuple(int(v) for v in np.rint(m)))
            f.write(encode_frame(p, i & 0xFF))
    out = tmp_path / "cal.json"
    png = tmp_path / "mag.png"
    assert main(["calibrate", "--capture", str(path), "--json", str(out), "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    assert "field norm before" in text and "SET_CALIBRATION block" in text
    doc = json.loads(out.read_text())
    block = doc["block"]
    assert np.allclose(block["gyro_bias"], truth["gbias"], atol=1)
    assert np.allclose(block["accel_offset"], truth["offset"], atol=1.5)
    assert np.allclose(block["mag_offset"], truth["hard"], atol=5)
    assert all(0.9 * 16384 < v < 1.1 * 16384 for v in block["accel_scale"])
    assert png.stat().st_size > 1000


def test_calibrate_command_refuses_a_missing_capture(tmp_path, capsys):
    from sphere.cli import main

    assert main(["calibrate", "--capture", str(tmp_path / "nope.bin")]) == 2
    assert "no such capture" in capsys.readouterr().err


# ---------------------------------------------------------------- the guided steps' detection (pure)

from sphere.calibration import session as session  # noqa: E402


def _series(acc, gyr, mag, rate=200.0, mag_every=3):
    acc, gyr, mag = (np.asarray(x, float) for x in (acc, gyr, mag))
    t = np.arange(len(acc)) / rate
    k = np.arange(0, len(acc), mag_every)
    return session.Series(t, acc, gyr, t[k], mag[k])


def _still(n, rng, up=(0, 0, 256.0), bias=(20.0, -15.0, 7.0), field=(200.0, 0.0, -450.0)):
    """n samples lying still: chip-like noise (gyro 5.5 LSB, accel 1.2 LSB, mag 2 LSB)."""
    return (np.asarray(up) + rng.normal(0, 1.2, (n, 3)), np.asarray(bias) + rng.normal(0, 5.5, (n, 3)),
            np.asarray(field) + rng.normal(0, 2.0, (n, 3)))


def _cat(*parts):
    return tuple(np.vstack([p[i] for p in parts]) for i in range(3))


def _moving(n, rng):
    return rng.normal(0, 150, (n, 3)), rng.normal(0, 3000, (n, 3)), _rotations(n, rng) @ np.array([200.0, 0, -450])


def test_still_spans_find_still_phases_in_device_time():
    rng = np.random.default_rng(10)
    s = _series(*_cat(_still(400, rng), _moving(200, rng), _still(600, rng)))  # 2 s, 1 s moving, 3 s
    spans = session.still_spans(s, min_s=1.0)
    assert [round(sp.seconds, 2) for sp in spans] == [2.0, 2.75]  # block-aligned: 0.25 s lost at the edge
    assert spans[1].t0 == 3.0 and spans[1].t1 == 5.75  # the block from 5.75 s is not complete yet
    tail = session.trailing_still(s)
    assert tail is not None and tail.t1 == spans[1].t1
    # the same samples at half the rate (a slower link, or the device's raw rate set lower) last twice as long
    s2 = _series(*_cat(_still(400, rng), _moving(200, rng), _still(600, rng)), rate=100.0)
    assert [round(sp.seconds, 2) for sp in session.still_spans(s2, min_s=1.0)] == [4.0, 5.75]


def test_a_slow_steady_turn_is_not_still():
    """Turning at 3 °/s about the vertical: the gyro is steady (only its bias changes), so is the
    accelerometer; the field's heading drifts, and that breaks the span."""
    rng = np.random.default_rng(11)
    n = 1200
    ang = np.radians(3.0) * np.arange(n) / 200.0
    field = np.stack([200 * np.cos(ang), -200 * np.sin(ang), np.full(n, -450.0)], 1) + rng.normal(0, 2, (n, 3))
    acc = np.array([0, 0, 256.0]) + rng.normal(0, 1.2, (n, 3))
    gyr = np.array([20.0, -15.0, 7.0 + 3.0 * 14.375]) + rng.normal(0, 5.5, (n, 3))
    assert max(sp.seconds for sp in session.still_spans(_series(acc, gyr, field))) < 3.0
    # without the magnetometer, tilting at 3 °/s is caught by the accelerometer's drift
    tilt = np.stack([256 * np.sin(ang), np.zeros(n), 256 * np.cos(ang)], 1) + rng.normal(0, 1.2, (n, 3))
    s = session.Series(np.arange(n) / 200.0, tilt, gyr, np.zeros(0), np.zeros((0, 3)))
    assert max(sp.seconds for sp in session.still_spans(s)) < 3.0


def test_classify_face():
    for i, (_, axis, sign) in enumerate(session.FACES):
        a = np.zeros(3)
        a[axis] = 250.0 * sign
        assert session.classify_face(a + 20.0) == i
    assert session.classify_face([180.0, 0.0, 180.0]) is None  # 45°: on an edge, not a face
    assert session.classify_face([5.0, 3.0, 2.0]) is None  # no gravity (falling, or no accelerometer)


def test_update_faces_ticks_faces_off_in_any_order():
    rng = np.random.default_rng(12)
    ups = {4: (0, 0, 256.0), 0: (256.0, 0, 0), 3: (0, -256.0, 0)}
    parts, seen = [], {}
    for face, up in ups.items():
        parts += [_moving(100, rng), _still(500, rng, up=up)]  # 2.5 s on each
        s = _series(*_cat(*parts))
        seen, now = session.update_faces(seen, s)
        assert face in seen and now.face == face and now.still_s >= session.FACE_S
    assert sorted(seen) == [0, 3, 4]
    assert session.missing_faces(seen) == ["−x up", "+y up", "−z up (upside down)"]
    # 1 s on a face is not enough; the progress says which face and for how long
    s = _series(*_cat(*parts, _moving(100, rng), _still(200, rng, up=(-256.0, 0, 0))))
    seen2, now = session.update_faces(seen, s)
    assert 1 not in seen2 and now.face == 1 and 0.5 <= now.still_s < session.FACE_S
    # a face seen again replaces the older sighting
    s = _series(*_cat(*parts, _moving(100, rng), _still(600, rng, up=(0, 0, 256.0))))
    seen3, _ = session.update_faces(seen, s)
    assert seen3[4].span.t0 > seen[4].span.t1 and seen3[4].samples >= 500


def test_field_coverage_and_the_turn_step():
    rng = np.random.default_rng(13)
    field, hard = np.array([200.0, 0.0, -450.0]), np.array([150.0, -90.0, 60.0])
    everywhere = _rotations(3000, rng) @ field + hard + rng.normal(0, 2, (3000, 3))
    assert session.field_coverage(everywhere).fraction > 0.95  # the hard iron does not skew the directions
    t = np.linspace(0, 2 * np.pi, 1500)
    ring = np.stack([490 * np.cos(t), 490 * np.sin(t), np.zeros_like(t)], 1) + hard + rng.normal(0, 2, (1500, 3))
    assert session.field_coverage(ring).fraction < 0.5  # one great circle: far from the target
    blob = field + hard + rng.normal(0, 2, (600, 3))
    assert session.field_coverage(blob).bins_hit == 0  # lying still: noise points anywhere, covers nothing
    # done at the target after the minimum time, or at the maximum time
    n = int(12 * 75)
    s = session.Series(np.arange(n) / 75.0, np.zeros((n, 3)), np.zeros((n, 3)), np.arange(n) / 75.0, everywhere[:n])
    st = session.turn_status(s.since(0.0))
    assert st.done and st.reason == "coverage"
    early = session.turn_status(session.Series(s.t[:300], s.accel[:300], s.gyro[:300], s.mag_t[:300], s.mag[:300]))
    assert not early.done and early.coverage.fraction > 0.5  # 4 s: covered, but the minimum is 8 s
    n = int(31 * 75)
    still = session.Series(np.arange(n) / 75.0, np.zeros((n, 3)), np.zeros((n, 3)), np.arange(n) / 75.0,
                           field + hard + rng.normal(0, 2, (n, 3)))
    st = session.turn_status(still)
    assert st.done and st.reason == "time" and st.coverage.bins_hit == 0


@pytest.mark.slow
def test_the_virtual_spheres_script_through_the_guided_steps():
    """synthetic:calibration in chip units (no board), fed to the steps as the samples would arrive:
    each step ends where the script says, the axis check passes (an aligned board), and the fits recover
    the injected imperfections."""
    from sphere.calibration import axis_check
    from sphere.sim import trace as T

    ct = T.to_chips(T.calibration(70.0))
    _, timeline = T.calibration_script(70.0)
    ends = {name: t1 for name, _, t1 in timeline}
    starts = {name: t0 for name, t0, _ in timeline}
    t = np.arange(len(ct.accel_lsb)) / ct.accel_rate_hz
    mag_t = np.arange(len(ct.mag_lsb)) / ct.mag_rate_hz
    full = session.Series(t, ct.accel_lsb.astype(float), ct.gyro_lsb.astype(float), mag_t, ct.mag_lsb.astype(float))

    def upto(t1):
        i, k = np.searchsorted(full.t, t1, "right"), np.searchsorted(full.mag_t, t1, "right")
        return session.Series(full.t[:i], full.accel[:i], full.gyro[:i], full.mag_t[:k], full.mag[:k])

    now, span = 0.5, None  # the host joins half a second in
    while span is None or span.seconds < session.STILL_S:
        now += 0.1
        span = session.trailing_still(upto(now).since(0.5))
    gyro_still = full.gyro[span.start + np.searchsorted(full.t, 0.5):][: span.stop - span.start]
    assert now < timeline[0][2]  # within the first still phase
    start, bias = now, gyro_still.mean(axis=0)
    while not (f := axis_check.fit(upto(now).since(start), bias, full=False)).done:
        now += 0.5
        assert now < ends["+x"], f
    assert now >= starts["turn z"] + T.CAL_SWING_S  # not before the third axis has turned a quarter turn
    v = axis_check.verdict(f, "aligned")
    assert v.ok and v.lines[0].startswith("axes agree"), v.lines
    start, seen = now, {}
    while len(seen) < 6:
        now += 0.1
        seen, _ = session.update_faces(seen, upto(now).since(start))
        assert now < starts["tumble"] + 1.0, session.missing_faces(seen)
    start = now
    while not (st := session.turn_status(upto(now).since(start))).done:
        now += 0.1
    assert st.reason == "coverage" and now < 69.0
    cal = session.calibrate(gyro_still, {k: v.mean for k, v in seen.items()}, upto(now).mag)
    assert not cal.notes
    assert np.allclose(cal.gyro.bias_lsb, T.CAL_GYRO_BIAS_DPS * chips.ITG3200_LSB_PER_DPS, atol=0.7)
    assert np.allclose(cal.accel.offset_lsb, T.CAL_ACCEL_OFFSET_G * 256, atol=0.3)
    assert np.allclose(cal.accel.gain, 1.0 / T.CAL_ACCEL_SCALE, rtol=1e-3)
    assert np.allclose(cal.mag.hard_iron_lsb, T.CAL_MAG_HARD_IRON_UT * chips.HMC5883L_LSB_PER_UT, atol=1.5)
    W = cal.mag.soft_iron @ T.CAL_MAG_SOFT_IRON
    assert np.allclose(W / np.cbrt(np.linalg.det(W)), np.eye(3), atol=0.01)


def test_synthetic_calibration_is_a_registered_source():
    from sphere.sim import trace as T

    m = T.synthetic("calibration", 40.0)
    assert m.seconds == pytest.approx(40.0) and m.name == "calibration"
    assert "calibration" in T.SYNTHETIC


def test_block_keeps_the_devices_values_for_parts_not_computed():
    from sphere.commands.calibrate import block_from

    rng = np.random.default_rng(14)
    c = cal.Calibration(gyro=cal.gyro_bias(np.array([3.0, 4.0, 5.0]) + rng.normal(0, 1, (100, 3))))
    base = {"gyro_bias": (1, 1, 1), "accel_offset": (5, 6, 7), "accel_scale": (16000, 16100, 16200),
            "mag_offset": (10, 20, 30), "mag_soft_iron": (16384, 0, 0, 0, 16384, 0, 0, 0, 16000)}
    b = block_from(c, base)
    assert b["gyro_bias"] == (3, 4, 5)
    assert {k: b[k] for k in base if k != "gyro_bias"} == {k: v for k, v in base.items() if k != "gyro_bias"}
    assert block_from(cal.Calibration())["accel_scale"] == (16384,) * 3  # no base: the defaults
