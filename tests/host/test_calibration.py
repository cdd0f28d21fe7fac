"""Calibration math recovers known synthetic parameters."""

from __future__ import annotations

import numpy as np
import pytest

from sphere import calibration as cal
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


class _FakeSphere:
    """A serial port double: streams RAW_SAMPLE frames for the pose named in ``phase`` and answers
    SET_CALIBRATION / SAVE_CALIBRATION with REPLY ok."""

    def __init__(self, rng):
        from sphere.protocol import FrameDecoder

        self.rng = rng
        self.phase = "still"
        self.t_us = 0
        self.seq = 0
        self.out = bytearray()
        self.host = FrameDecoder("host")
        self.received = []
        self.offset, self.sens = np.array([5.0, -8.0, 10.0]), np.array([255.0, 258.0, 250.0])
        self.gbias = np.array([20.0, -15.0, 7.0])
        self.field, self.hard = np.array([200.0, 0.0, -450.0]), np.array([40.0, -60.0, 15.0])
        self.faces = {0: [1, 0, 0], 1: [-1, 0, 0], 2: [0, 1, 0], 3: [0, -1, 0], 4: [0, 0, 1], 5: [0, 0, -1]}
        self.in_waiting = 0

    def _sample(self):
        from sphere.protocol import RawSample, encode_frame

        rng = self.rng
        if self.phase == "turning":
            R = _rotations(1, rng)[0]
            acc = R.T @ np.array([0, 0, 1.0]) * self.sens + self.offset
            gyr = rng.normal(0, 500, 3)
            mag = R @ self.field + self.hard
        else:
            face = 4 if self.phase == "still" else next(i for i, n in enumerate(FACE_NAMES) if n == self.phase)
            acc = np.array(self.faces[face]) * self.sens + self.offset + rng.normal(0, 1.0, 3)
            gyr = self.gbias + rng.normal(0, 2.0, 3)
            mag = self.field + self.hard
        self.t_us += 5000
        self.seq = (self.seq + 1) & 0xFF
        p = RawSample(t_us=self.t_us, flags=0b1111, accel=tuple(int(v) for v in np.rint(acc)),
                      gyro=tuple(int(v) for v in np.rint(gyr)), mag=tuple(int(v) for v in np.rint(mag)))
        return encode_frame(p, self.seq)

    def read(self, n=1):
        import time as _t

        _t.sleep(0.002)
        return b"".join(self._sample() for _ in range(4)) + self._pop()

    def _pop(self):
        data, self.out = bytes(self.out), bytearray()
        return data

    def write(self, data):
        from sphere.protocol import Reply, encode_frame

        for p in self.host.feed(data):
            self.received.append(p)
            self.out += encode_frame(Reply(cmd_seq=p.seq, cmd_type=p.TYPE, result=0), 0)

    def close(self):
        pass


FACE_NAMES = None


def test_calibrate_port_session_sends_and_saves(monkeypatch, capsys):
    """The guided --port flow against a fake sphere: every step, then SET_CALIBRATION and SAVE_CALIBRATION."""
    global FACE_NAMES
    from sphere import serial_link
    from sphere.cli import main
    from sphere.commands import calibrate

    FACE_NAMES = calibrate.FACES
    port = _FakeSphere(np.random.default_rng(6))
    monkeypatch.setattr(serial_link, "open_port", lambda *a, **k: port)
    monkeypatch.setattr(calibrate, "STILL_S", 0.4)
    monkeypatch.setattr(calibrate, "FACE_S", 0.3)
    monkeypatch.setattr(calibrate, "TURN_S", 1.5)
    original = calibrate._record

    def record(link, seconds, label):
        port.phase = label
        return original(link, seconds, label)

    monkeypatch.setattr(calibrate, "_record", record)
    assert main(["calibrate", "--port", "FAKE", "--yes"]) == 0
    names = [p.NAME for p in port.received]
    assert names[-2:] == ["SET_CALIBRATION", "SAVE_CALIBRATION"]
    block = port.received[-2]
    assert np.allclose(block.gyro_bias, port.gbias, atol=1)
    assert np.allclose(block.accel_offset, port.offset, atol=2)
    assert np.allclose(block.mag_offset, port.hard, atol=8)
    assert "saved to EEPROM" in capsys.readouterr().err
