"""A scripted sphere: wire frames for a motion described step by step, for tests, the benchmark and
``--simulate`` when the virtual board is not installed.

    frames = script_frames([("still", 1.0), ("turn", (0, 0, 1), 10.0, 1.0), ("tap", "single_tap"),
                            ("free_fall", 0.3), ("tilt", (0, 1, 0), -15.0, 0.5)])
    data = b"".join(f for _, f in frames)

Each step: ``("still", s)``; ``("turn", axis, dps, s)`` (constant rate about a sensor axis);
``("tilt", axis, deg, s)`` (turn by an angle over s at constant rate); ``("tap", name)`` with name
``single_tap``/``double_tap`` (a short gyro jolt flagged ``tap_active``, then the EVENT);
``("free_fall", s)`` (no gravity, a spin, then the EVENT).
The samples are physically consistent: accelerometer = gravity in sensor axes, magnetometer = the
earth's field in sensor axes, ORIENTATION = the true orientation (sensor-to-NWU) at half the rate.
"""

from __future__ import annotations

import math

from sphere import chips
from sphere import quaternion
from sphere.protocol import Event, Hello, Orientation, RawSample, Status, encode_frame
from sphere.protocol.packets import (CAL_GYRO_BIAS_ESTIMATED, CAL_GYRO_BIAS_VALID, ORI_MAG_USED, RAW_ACCEL_OK, RAW_GYRO_OK,
                                     RAW_MAG_FRESH, RAW_MAG_OK, RAW_TAP_ACTIVE, SENSOR_ADXL345, SENSOR_HMC5883L,
                                     SENSOR_ITG3200, STREAM_ORIENTATION, STREAM_RAW, STREAM_STATUS)

EARTH_FIELD_NWU_UT = (20.0, 0.0, -44.0)
_ALL_SENSORS = SENSOR_ADXL345 | SENSOR_ITG3200 | SENSOR_HMC5883L
_CALIBRATION_STATE = CAL_GYRO_BIAS_VALID | CAL_GYRO_BIAS_ESTIMATED  # the device measured its gyro bias at start
EVENT_CODES = {"single_tap": 1, "double_tap": 2, "free_fall": 3}


def hello_packet(raw_rate_hz=200, orientation_rate_hz=100) -> Hello:
    return Hello(
        protocol_version=1, firmware_version=(0, 1, 0), sensors_found=_ALL_SENSORS, adxl345_devid=0xE5, itg3200_whoami=0x69,
        hmc5883l_id=tuple(b"H43"), imu_rate_hz=200, mag_rate_hz=75, stream_mode=STREAM_RAW | STREAM_ORIENTATION | STREAM_STATUS, raw_rate_hz=raw_rate_hz,
        orientation_rate_hz=orientation_rate_hz, calibration_state=_CALIBRATION_STATE,
    )


def _to_sensor(q, v):
    """Earth vector v in sensor coordinates: Rᵀ v for the sensor-to-earth rotation q."""
    w, x, y, z = q
    r = ((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
         (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
         (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))
    return tuple(r[0][i] * v[0] + r[1][i] * v[1] + r[2][i] * v[2] for i in range(3))


def _clip16(v):
    return max(-32768, min(32767, int(round(v))))


class ScriptedSphere:
    """Produces (t_us, frame_bytes) for a script; keeps the sequence counter and the orientation."""

    def __init__(self, imu_rate_hz: int = 200, orientation_every: int = 2, status_every_s: float = 1.0,
                 quat=(1.0, 0.0, 0.0, 0.0), t0_us: int = 1_000_000, seq0: int = 0):
        self.rate = imu_rate_hz
        self.orientation_every = orientation_every
        self.status_every_us = int(status_every_s * 1e6) if status_every_s else 0
        self.q = tuple(quat)
        self.t_us = t0_us
        self.seq = seq0
        self.n = 0
        self._next_status = t0_us + self.status_every_us

    def frame(self, packet) -> bytes:
        f = encode_frame(packet, self.seq)
        self.seq = (self.seq + 1) & 0xFF
        return f

    def hello(self):
        return (self.t_us, self.frame(hello_packet(self.rate, self.rate // self.orientation_every)))

    def sample(self, rate_dps=(0.0, 0.0, 0.0), falling=False, tap_active=False):
        """One sample period: rotate by rate_dps for 1/rate s, then emit RAW (and ORIENTATION, STATUS)."""
        dt = 1.0 / self.rate
        wx, wy, wz = (math.radians(v) for v in rate_dps)
        ang = math.sqrt(wx * wx + wy * wy + wz * wz) * dt
        if ang > 0:
            s = math.sin(ang / 2) / (ang / dt)
            self.q = quaternion.mul(self.q, (math.cos(ang / 2), wx * s, wy * s, wz * s))
            n = math.sqrt(sum(v * v for v in self.q))
            self.q = tuple(v / n for v in self.q)
        self.t_us += int(round(1e6 / self.rate))
        t = self.t_us & 0xFFFFFFFF
        up = (0.0, 0.0, 0.0) if falling else _to_sensor(self.q, (0.0, 0.0, 1.0))
        mag = _to_sensor(self.q, EARTH_FIELD_NWU_UT)
        flags = (RAW_ACCEL_OK | RAW_GYRO_OK | RAW_MAG_OK | (RAW_MAG_FRESH if self.n % 3 == 0 else 0)
                 | (RAW_TAP_ACTIVE if tap_active else 0))
        raw = RawSample(
            t_us=t, flags=flags,
            accel=tuple(_clip16(v * chips.ADXL345_LSB_PER_G) for v in up),
            gyro=tuple(_clip16(v * chips.ITG3200_LSB_PER_DPS) for v in rate_dps),
            mag=tuple(_clip16(v * chips.HMC5883L_LSB_PER_UT) for v in mag),
        )
        out = [(self.t_us, self.frame(raw))]
        if self.n % self.orientation_every == 0:
            quat = tuple(_clip16(v * 16384.0) for v in self.q)
            out.append((self.t_us, self.frame(Orientation(t_us=t, flags=ORI_MAG_USED, quat=quat))))
        if self.status_every_us and self.t_us >= self._next_status:
            self._next_status += self.status_every_us
            out.append((self.t_us, self.frame(Status(
                t_us=t, sensors_ok=_ALL_SENSORS, i2c_errors=(0, 0, 0), i2c_recoveries=0, loop_overruns=0, frames_dropped=0,
                rx_errors=0, calibration_state=_CALIBRATION_STATE, calibration_step=0, cpu_load=420, battery_mv=3900))))
        self.n += 1
        return out

    def event(self, name: str):
        code = EVENT_CODES[name]
        status = {"single_tap": 0x40, "double_tap": 0x20, "free_fall": 0x04}[name]
        ev = Event(t_us=self.t_us & 0xFFFFFFFF, event=code, int_source=status | 0x80,
                   act_tap_status=0x01 if code != 3 else 0, tap_sign=1 if code != 3 else 0)
        return [(self.t_us, self.frame(ev))]

    def steps(self, script):
        """All frames of a script at once: [(t_us, frame_bytes)]."""
        return [frame for sample in self.iter_steps(script) for frame in sample]

    def iter_steps(self, script):
        """The frames of a script one sample period at a time (lists of (t_us, frame_bytes)), computed lazily."""
        for step in script:
            yield from self._step_lists(step)

    def _step_lists(self, step):
        kind = step[0]
        if kind == "still":
            for _ in range(int(round(step[1] * self.rate))):
                yield self.sample()
        elif kind == "turn":
            _, axis, dps, secs = step
            n = math.sqrt(sum(a * a for a in axis))
            rate = tuple(a / n * dps for a in axis)
            for _ in range(int(round(secs * self.rate))):
                yield self.sample(rate)
        elif kind == "tilt":
            _, axis, deg, secs = step
            yield from self._step_lists(("turn", axis, deg / secs, secs))
        elif kind == "tap":
            name = step[1]
            # the knock: a short jolt while the firmware flags tap_active, then the event
            # (the first sample of the knock comes before the chip has seen the tap)
            for i, rate in enumerate(((0, 0, 250.0), (0, 150.0, -250.0), (0, -150.0, 0))):
                yield self.sample(rate, tap_active=i > 0)
            yield self.sample() + self.event(name)
        elif kind == "free_fall":
            n = int(round(step[1] * self.rate))
            for _ in range(n):
                yield self.sample((300.0, 0.0, 0.0), falling=True)
            yield self.event("free_fall")
            # the spin undone while catching, so the sphere ends as it started
            for _ in range(n):
                yield self.sample((-300.0, 0.0, 0.0))
        else:
            raise ValueError(f"unknown script step {step!r}")


def script_frames(script, with_hello: bool = True, **kwargs):
    """[(t_us, frame_bytes)] for a whole script (see the module docstring)."""
    sphere = ScriptedSphere(**kwargs)
    out = [sphere.hello()] if with_hello else []
    return out + sphere.steps(script)


def script_bytes(script, **kwargs) -> bytes:
    return b"".join(f for _, f in script_frames(script, **kwargs))


#: A gentle demonstration for ``--simulate`` without the virtual board: slow circles, a tap, a pause.
DEMO_SCRIPT = [
    ("still", 1.0),
    ("turn", (0, 0, 1), 20.0, 1.0),
    ("turn", (0, 1, 0), 15.0, 1.0),
    ("turn", (0, 0, 1), -20.0, 1.0),
    ("turn", (0, 1, 0), -15.0, 1.0),
    ("still", 0.5),
    ("tap", "single_tap"),
    ("still", 1.0),
]
