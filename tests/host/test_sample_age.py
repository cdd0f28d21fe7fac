"""Sample age through the user's path: `sphere monitor` and sphere-mouse against a version-3 device on a pty
whose samples are a known age when written and whose clock is far from the host's and runs 0.3 % fast."""

from __future__ import annotations

import os
import re
import select
import subprocess
import sys
import threading
import time
import tty

import pytest

from sphere.daemon.scripted_sphere import hello_packet
from sphere.protocol import Echo, FrameDecoder, RawSample, Reply, encode_frame

AGE_S = 0.004  # each sample is this old when its frame is written


class AgedSphere:
    """A version-3 sphere: RAW_SAMPLE every 5 ms stamped AGE_S before it is written, ECHO answered at once with
    its clock (1e9 µs ahead of the host's and 0.3 % fast)."""

    def __init__(self, seconds: float):
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.path = os.ttyname(slave)
        os.close(slave)
        self.seconds = seconds
        self.echoes = 0
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    @staticmethod
    def device_us(host_s: float) -> int:
        return int((1000.0 + host_s * 1.003) * 1e6) % (1 << 32)

    def _run(self):
        seq, t_end = 0, time.monotonic() + self.seconds
        dec = FrameDecoder("host")
        hello = hello_packet()
        hello.protocol_version = 3
        next_sample = time.monotonic()
        sent_hello = False
        while time.monotonic() < t_end:
            r, _, _ = select.select([self.master], [], [], max(0.0, next_sample - time.monotonic()))
            out = b""
            if r:
                try:
                    data = os.read(self.master, 256)
                except OSError:
                    data = b""
                for p in dec.feed(data):
                    if p.NAME == "GET_HELLO":
                        out += encode_frame(Reply(p.seq, p.TYPE, 0), seq) + encode_frame(hello, (seq + 1) & 0xFF)
                        seq = (seq + 2) & 0xFF
                        sent_hello = True
                    elif p.NAME == "ECHO":
                        now = self.device_us(time.monotonic())
                        out += encode_frame(Reply(p.seq, Echo.TYPE, 0, data=now.to_bytes(4, "little")), seq)
                        seq = (seq + 1) & 0xFF
                        self.echoes += 1
            if sent_hello and time.monotonic() >= next_sample:
                next_sample += 0.005
                t_us = self.device_us(time.monotonic() - AGE_S)
                out += encode_frame(RawSample(t_us, 0x07, (0, 0, 256), (0, 0, 0), (300, 0, -400)), seq)
                seq = (seq + 1) & 0xFF
            if out:
                try:
                    os.write(self.master, out)
                except OSError:
                    return


@pytest.mark.slow
def test_sphere_monitor_shows_the_age_of_samples():
    dev = AgedSphere(8.0)
    r = subprocess.run([sys.executable, "-m", "sphere.cli", "monitor", "--port", dev.path, "--seconds", "6"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert dev.echoes >= 4  # twice a second once the HELLO said version 3
    m = re.search(r"sample age: median ([\d.]+) ms, p95 ([\d.]+) ms \(last 2 s", r.stdout)  # the final view
    assert m, r.stdout[-2000:]
    median_ms = float(m.group(1))
    # the age written into the samples, plus the pty and the monitor's read (a fraction of a ms on an idle
    # machine, a few on one shared by many jobs); the clock offset (1000 s) and the 0.3 % rate are taken out by
    # the ECHO fit: without it the figure would be off by seconds
    assert AGE_S * 1e3 - 1.0 <= median_ms <= AGE_S * 1e3 + 3.0, r.stdout[-800:]


def test_sphere_mouse_status_line_reports_the_age():
    """The daemon's serial source asks the clock with ECHO and its status line carries median/p95 age."""
    from sphere.daemon.app import SphereMouse
    from sphere.daemon.backends.memory import RecordingBackend
    from sphere.daemon.config import Config
    from sphere.daemon.sources.serial import SerialSource
    from sphere.daemon.status import StatusLine

    dev = AgedSphere(8.0)
    src = SerialSource(dev.path, hello_timeout_s=0.15, discovery_timeout_s=2.0, link_timeout_s=2.0,
                       reconnect_interval_s=0.1)
    cfg = Config().with_overrides({"outputs.page": {"enabled": False}}, "test")
    daemon = SphereMouse(cfg, src, RecordingBackend(), log=lambda m: None)
    t = threading.Thread(target=daemon.run, daemon=True)
    t.start()
    try:
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and (src.sample_age_ms() is None or dev.echoes < 6):
            time.sleep(0.1)
        age = src.sample_age_ms()
        assert age is not None, "no age: the ECHO round trips did not give a clock"
        assert AGE_S * 1e3 - 1.0 <= age[0] <= AGE_S * 1e3 + 3.0, age
        import io

        line = StatusLine(io.StringIO(), overwrite=False).text(daemon)
        assert re.search(r"age [\d.]+/[\d.]+ ms", line), line
    finally:
        daemon.stop()
        t.join(5)
