"""The demo's `synthetic:tour` on the real firmware in the virtual board, then through sphere-mouse: the
pointer goes right, left, up and down and comes back; a tap clicks, a double tap double-clicks; tosses
step through tilt (the pointer glides while the sphere is held turned) and 3-D (the page's URL is
printed; the pointer is left alone) and back to pointer."""

import subprocess
import sys

import pytest

from sphere.sim import tour

from simscenarios import need_board, need_firmware

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def tour_capture(tmp_path_factory):
    need_board()
    need_firmware()
    cap = tmp_path_factory.mktemp("tour") / "tour.cap"
    r = subprocess.run([sys.executable, "-m", "sphere.cli", "sim", "--trace", "synthetic:tour", "--seconds",
                        f"{tour.TOUR_S:.1f}", "--capture", str(cap)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return cap


def _windows():
    """(start, end, what) of each step of one round, from the script itself."""
    steps = tour.tour_script(100.0).steps
    return [(t0, t1, what) for (t0, what), (t1, _) in zip(steps, steps[1:] + [(tour.TOUR_S, "")])]


def test_the_tour_through_sphere_mouse(tour_capture):
    from sphere.daemon.app import SphereMouse
    from sphere.daemon.backends.memory import RecordingBackend
    from sphere.daemon.config import Config
    from sphere.daemon.sources.replay import ReplaySource

    log = []

    class Recorder(RecordingBackend):
        daemon = None

        def move(self, dx, dy):
            super().move(dx, dy)
            log.append((self.daemon.now_us / 1e6, dx, dy, self.daemon.mode))

        def click(self, button="left", count=1):
            super().click(button, count)
            log.append((self.daemon.now_us / 1e6, "click", count, self.daemon.mode))

    backend = Recorder()
    cfg = Config().with_overrides({"outputs.page": {"enabled": False}}, "test")
    d = SphereMouse(cfg, ReplaySource(tour_capture, speed=0), backend, log=lambda m: None)
    backend.daemon = d
    d.run()
    assert d.mode_changes == ["tilt", "3d", "pointer"]

    def moved(t0, t1, half=None):
        """Sum of pointer moves in [t0, t1) (half = 0 or 1: the first or second half of a there-and-back)."""
        if half is not None:
            t0, t1 = (t0, t0 + 1.2) if half == 0 else (t0 + 1.2, t1)
        sel = [(dx, dy) for t, dx, dy, _ in log if dx != "click" and t0 <= t < t1]
        return sum(x for x, _ in sel), sum(y for _, y in sel)

    w = {what: (t0, t1) for t0, t1, what in _windows()}
    # 20° at 40° per screen width (1920 px) = 960 px; 12° = 576 px; each comes back within a few px
    for what, sign, axis, px in (("pointer right and back", +1, 0, 960), ("pointer left and back", -1, 0, 960),
                                 ("pointer up and back", -1, 1, 576), ("pointer down and back", +1, 1, 576)):
        out, back = moved(*w[what], half=0), moved(*w[what], half=1)
        assert sign * out[axis] > 0.8 * px and abs(out[1 - axis]) < 0.05 * px, (what, out)
        assert abs(out[axis] + back[axis]) < 0.05 * px, (what, out, back)
    clicks = [(t, n) for t, kind, n, _ in log if kind == "click"]
    t_tap, t_double = w["tap: a click"][0], w["double tap: a double click"][0]
    assert [n for t, n in clicks if t_tap <= t < t_double] == [1]
    assert sum(n for t, n in clicks if t_double <= t < w["toss: tilt mode"][0]) == 2  # the desktop's double click
    glide_right = moved(*w["turned right and held: the pointer glides right"])
    glide_down = moved(*w["nose down and held: the pointer glides down"])
    assert glide_right[0] > 300 and abs(glide_right[1]) < 30, glide_right
    assert glide_down[1] > 300 and abs(glide_down[0]) < 30, glide_down
    t3d = w["toss: 3-D mode (open the page)"][0] + 1.0
    assert not [m for m in log if t3d <= m[0] < w["toss: back to pointer mode"][0] and m[1] != "click"]


def test_the_3d_mode_prints_the_page_url(tour_capture):
    r = subprocess.run([sys.executable, "-m", "sphere.mouse", "--config", "/dev/null", "--replay", str(tour_capture),
                        "--speed", "0", "--backend", "log", "--stream-port", "0"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "mode 3d (the 3-D view: http://127.0.0.1:" in r.stderr, r.stderr
    assert len(r.stdout.splitlines()) < 40  # a summary a second, not a line per move
