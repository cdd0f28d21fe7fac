"""`sphere monitor` through its command line against a pty that streams like a sphere: --plot and --plot-out
(an image without a display, refused before the port when they cannot work), and the rates of its last view."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
import time
import tty

import pytest

from sphere import paths
from sphere.link.port import holders

pytestmark = pytest.mark.slow  # each case runs the command on a paced stream for a few seconds


class PacedSphere:
    """A pty fed with the shipped example capture at its own pace (200 RAW_SAMPLE a second) from the moment a
    program opens it until the test ends: like a serial port, which receives once it is open, whether anyone
    reads it then or not."""

    def __init__(self):
        self.data = paths.resolve_capture("example:broad_fast_rotation_4s").read_bytes()
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.path = os.ttyname(slave)
        os.close(slave)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._feed, daemon=True)
        self.thread.start()

    def _feed(self):
        while not self.stop.is_set() and not holders(self.path):
            time.sleep(0.005)
        per_s = len(self.data) / 4.0  # the capture is four seconds of the device's stream
        t0, k, sent = time.monotonic(), 0, 0
        while not self.stop.is_set():
            k += 1
            due = int(k * 0.005 * per_s)
            chunk = bytes(self.data[(sent + j) % len(self.data)] for j in range(due - sent))
            sent = due
            try:
                os.write(self.master, chunk)
            except OSError:
                pass  # nobody reading: the pty's buffer is full, as a port's would be
            time.sleep(max(0.0, t0 + k * 0.005 - time.monotonic()))

    def close(self):
        self.stop.set()
        self.thread.join(5)
        os.close(self.master)


@pytest.fixture
def sphere_pty():
    s = PacedSphere()
    yield s
    s.close()


def monitor(*argv, display=""):
    env = dict(os.environ, DISPLAY=display)
    for k in ("MPLBACKEND", "WAYLAND_DISPLAY"):
        env.pop(k, None)
    return subprocess.run([sys.executable, "-m", "sphere.cli", "monitor", *argv], capture_output=True, text=True,
                          timeout=120, env=env)


def test_plot_out_alone_writes_the_image_and_the_rates_are_of_the_stream(sphere_pty, tmp_path):
    """--plot-out without --plot, no display: the image is written, and the last view's rates and counts are the
    stream's (matplotlib is set up before the port is opened, so no burst of what the port buffered meanwhile;
    without a window nothing is drawn while reading, so no stall at the end)."""
    pytest.importorskip("matplotlib")
    png = tmp_path / "view.png"
    r = monitor("--port", sphere_pty.path, "--seconds", "2", "--plot-out", str(png))
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    m = re.search(r"RAW_SAMPLE (\d+) \((\d+)/s\)", r.stdout)
    assert m, r.stdout
    count, rate = int(m.group(1)), int(m.group(2))
    assert 150 <= rate <= 250, r.stdout  # the device sends 200 a second
    assert count <= 2 * 200 * 1.15, r.stdout  # 2 s of stream, not also what piled up before the first read


@pytest.mark.parametrize("argv, words", [
    (["--plot"], "no window to draw in"),  # no display: nothing would show
    (["--plot-out", "{tmp}/view.pngg"], "image format matplotlib writes"),
    (["--plot", "--plot-out", "{tmp}/view"], "image format matplotlib writes"),
    (["--plot-out", "/proc/sphere-view.png"], "cannot be written"),
    (["--plot-out", "{tmp}"], "is a folder"),
])
def test_plot_that_cannot_work_is_refused_before_the_port(sphere_pty, tmp_path, argv, words):
    pytest.importorskip("matplotlib")
    t = time.monotonic()
    r = monitor("--port", sphere_pty.path, "--seconds", "90", *[a.replace("{tmp}", str(tmp_path)) for a in argv])
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip() and not ln.startswith(("usage:", " "))]
    assert words in r.stderr and len(lines) == 1, r.stderr
    assert time.monotonic() - t < 60  # refused, not run for its 90 s
    assert not list(tmp_path.iterdir())
