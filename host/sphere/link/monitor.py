"""What ``sphere monitor`` shows of a live link, computed from the packets (pure logic, no port):
packets per type and their rate, the sensor flags, the latest values, events as they come, link quality.

    mon = LinkMonitor()
    for dp in stream.feed(chunk):
        mon.packet(dp, wall_s)        # returns a line for an event/HELLO/REPLY, else None
    mon.lines(wall_s)                  # the current view, a list of text lines
    mon.summary(wall_s)                # one line (for a log or a pipe)
"""

from __future__ import annotations

import collections
import math

from sphere.link.clock import SampleAges
from sphere.protocol.packets import Echo
from sphere.protocol.packets import EVENT_NAMES, ORIENTATION_FLAGS, RAW_FLAGS, SENSOR_BITS, bit_names

RATE_WINDOW_S = 2.0


def euler_deg(q) -> tuple[float, float, float]:
    """Heading (about z, left +), pitch (nose up +), roll (right side down +) of a sensor-to-NWU quaternion."""
    w, x, y, z = q
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    about_y = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    return math.degrees(yaw), -math.degrees(about_y), math.degrees(roll)


class LinkMonitor:
    def __init__(self, decoder_stats=None, history_s: float = 10.0):
        self.stats = decoder_stats  # the frame decoder's counters (DecoderStats), read live
        self.counts: collections.Counter = collections.Counter()
        self.times: dict[str, collections.deque] = collections.defaultdict(collections.deque)
        self.latest: dict[str, object] = {}
        self.events: collections.deque = collections.deque(maxlen=5)
        self.hello = None
        self.first_wall = None
        self.history_s = history_s
        #: recent samples for a plot: (device s, accel g ×3, gyro °/s ×3, mag µT ×3)
        self.raw_history: collections.deque = collections.deque(maxlen=4000)
        self.quat_history: collections.deque = collections.deque(maxlen=2000)
        #: each RAW_SAMPLE's age on arrival (sphere.link.clock), once the device clock is known
        self.ages = SampleAges()
        self.clock_uncertainty_s: float | None = None

    def sample_age(self, age_s: float, wall_s: float) -> str | None:
        """Note a RAW_SAMPLE's age on arrival; a line when it starts or stops growing."""
        return self.ages.add(age_s, wall_s)

    def age_line(self) -> str | None:
        now = self.ages.percentiles_ms()
        if now is None:
            return None
        med, p95 = self.ages.run_percentiles_ms()
        run = f"; over the run median {med:.2f} ms, p95 {p95:.2f} ms ({self.ages.run_samples} samples)"
        clock = f", device clock ±{self.clock_uncertainty_s * 1e3:.2f} ms" if self.clock_uncertainty_s is not None else ""
        return f"sample age: median {now[0]:.2f} ms, p95 {now[1]:.2f} ms (last {self.ages.keep_s:g} s{clock}){run}"

    def packet(self, dp, wall_s: float) -> str | None:
        p = dp.packet
        name = p.NAME
        if self.first_wall is None:
            self.first_wall = wall_s
        self.counts[name] += 1
        q = self.times[name]
        q.append(wall_s)
        while q and wall_s - q[0] > RATE_WINDOW_S:
            q.popleft()
        self.latest[name] = p
        t_s = dp.t_us / 1e6 if dp.t_us is not None else None
        if name == "RAW_SAMPLE" and t_s is not None:
            self.raw_history.append((t_s, *p.accel_g, *p.gyro_dps, *p.mag_uT))
        elif name == "ORIENTATION" and t_s is not None:
            self.quat_history.append((t_s, *p.quat_float))
        elif name == "EVENT":
            axes = "".join(p.tap_axes)
            text = f"{t_s:10.3f} s  {EVENT_NAMES.get(p.event, p.event)}" + (f" ({axes})" if axes else "")
            self.events.append(text)
            return f"event {text.strip()}"
        elif name == "HELLO":
            self.hello = p
            j = p.to_json()
            return (f"HELLO seq {p.seq}: firmware {j['firmware_version']}, protocol {p.protocol_version}, sensors "
                    f"{', '.join(j['sensors_found']) or 'none'}, stream {', '.join(j['stream_mode']) or 'off'}")
        elif name == "REPLY":
            if p.cmd_type == Echo.TYPE and p.ok:  # the monitor's own clock queries (twice a second)
                return None
            j = p.to_json()
            return f"REPLY to {j['cmd_type']} (seq {p.cmd_seq}): {j['result']}"
        return None

    def rate_hz(self, name: str, wall_s: float) -> float:
        q = self.times.get(name)
        if not q:
            return 0.0
        recent = [t for t in q if wall_s - t <= RATE_WINDOW_S]
        span = min(RATE_WINDOW_S, wall_s - (self.first_wall if self.first_wall is not None else wall_s))
        return len(recent) / span if span > 0.2 else 0.0

    def quality(self) -> str:
        s = self.stats
        if s is None:
            return ""
        return (f"frames ok {s.frames_ok}, CRC errors {s.crc_errors}, framing errors {s.framing_errors}, "
                f"frames lost {s.frames_lost} (in {s.seq_gaps} gaps), bytes skipped {s.bytes_skipped}")

    def lines(self, wall_s: float) -> list[str]:
        out = []
        h = self.hello
        if h is not None:
            j = h.to_json()
            out.append(f"sphere: firmware {j['firmware_version']}, protocol {h.protocol_version}, sensors "
                       f"{', '.join(j['sensors_found']) or 'none'}, IMU {h.imu_rate_hz} Hz")
        else:
            out.append("sphere: no HELLO yet")
        rates = "  ".join(f"{n} {self.counts[n]} ({self.rate_hz(n, wall_s):.0f}/s)" for n in sorted(self.counts))
        out.append(f"packets: {rates or 'none yet'}")
        raw = self.latest.get("RAW_SAMPLE")
        if raw is not None:
            out.append(f"flags: {' '.join(bit_names(raw.flags, RAW_FLAGS)) or '-'}")
            a, g, m = raw.accel_g, raw.gyro_dps, raw.mag_uT
            out.append(f"accel g   {a[0]:+7.3f} {a[1]:+7.3f} {a[2]:+7.3f}   |a| {math.hypot(*a):.3f}")
            out.append(f"gyro °/s  {g[0]:+7.2f} {g[1]:+7.2f} {g[2]:+7.2f}")
            out.append(f"mag µT    {m[0]:+7.1f} {m[1]:+7.1f} {m[2]:+7.1f}   |m| {math.hypot(*m):.1f}")
        ori = self.latest.get("ORIENTATION")
        if ori is not None:
            yaw, pitch, roll = euler_deg(ori.quat_float)
            out.append(f"orientation  heading {yaw:+7.1f}°  pitch {pitch:+6.1f}°  roll {roll:+7.1f}°   "
                       f"{' '.join(bit_names(ori.flags, ORIENTATION_FLAGS)) or '-'}")
        st = self.latest.get("STATUS")
        if st is not None:
            out.append(f"status: sensors ok {', '.join(bit_names(st.sensors_ok, SENSOR_BITS)) or 'none'}, I2C errors "
                       f"{'/'.join(map(str, st.i2c_errors))}, overruns {st.loop_overruns}, dropped {st.frames_dropped}, "
                       f"cpu {st.cpu_load / 10:.1f} %")
        q = self.quality()
        if q:
            out.append(f"link: {q}")
        age = self.age_line()
        if age:
            out.append(age)
        out.append("events: " + ("  |  ".join(e.strip() for e in self.events) if self.events else "none yet"))
        return out

    def summary(self, wall_s: float) -> str:
        rates = ", ".join(f"{n} {self.rate_hz(n, wall_s):.0f}/s" for n in sorted(self.counts))
        raw = self.latest.get("RAW_SAMPLE")
        flags = f"; flags {' '.join(bit_names(raw.flags, RAW_FLAGS))}" if raw is not None else ""
        q = self.quality()
        ages = self.ages.percentiles_ms()
        age = f"; sample age median {ages[0]:.2f} ms, p95 {ages[1]:.2f} ms" if ages else ""
        return f"{rates or 'no packets'}{flags}" + (f"; {q}" if q else "") + age

