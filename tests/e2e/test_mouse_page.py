"""The 3-D page in headless Chromium (software WebGL): three.js loads from the daemon itself (no network),
the page connects to the WebSocket, and the sphere it draws turns and moves with the stream."""

from __future__ import annotations

import base64
import json
import math
import shutil
import subprocess
import threading
import time
import urllib.request

import pytest

pytest.importorskip("websockets", reason="the 3-D stream needs websockets (pip install websockets)")

from sphere.daemon.stream3d import OrientationStream  # noqa: E402

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="needs Chromium (apt-get install chromium)")


class HeadlessChromium:
    """Chromium with the DevTools protocol on a local port, to read the live page (no virtual time)."""

    def __init__(self, url: str, profile):
        self.proc = subprocess.Popen(
            [CHROMIUM, "--headless", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
             "--no-first-run", "--remote-debugging-port=0",
             f"--user-data-dir={profile}", "--window-size=800,600", url],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        port_file = profile / "DevToolsActivePort"
        deadline = time.monotonic() + 30
        while not port_file.exists() or not port_file.read_text().strip():
            if time.monotonic() > deadline:
                self.close()
                pytest.fail("Chromium did not open its DevTools port")
            time.sleep(0.05)
        self.port = int(port_file.read_text().split()[0])
        self._id = 0

    def _page_ws(self) -> str:
        with urllib.request.urlopen(f"http://127.0.0.1:{self.port}/json/list", timeout=5) as r:
            pages = [p for p in json.load(r) if p.get("type") == "page"]
        return pages[0]["webSocketDebuggerUrl"]

    def call(self, method: str, **params):
        from websockets.sync.client import connect

        with connect(self._page_ws(), max_size=None) as ws:
            self._id += 1
            ws.send(json.dumps({"id": self._id, "method": method, "params": params}))
            while True:
                reply = json.loads(ws.recv(timeout=10))
                if reply.get("id") == self._id:
                    return reply.get("result", {})

    def text(self, ident: str) -> str:
        r = self.call("Runtime.evaluate", expression=f"document.getElementById({ident!r}).textContent")
        return r.get("result", {}).get("value", "")

    def screenshot(self, path) -> None:
        data = self.call("Page.captureScreenshot", format="png")["data"]
        path.write_bytes(base64.b64decode(data))

    def close(self):
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def test_page_connects_and_turns_with_the_sphere(tmp_path):
    stream = OrientationStream("127.0.0.1", 0, rate_hz=60)
    stream.mode = "3d"
    stream.start()
    stop = threading.Event()

    def sphere():
        # the pose held while the page connects is its reference; then the sphere turns 30° to the left
        while not stream.clients and not stop.is_set():
            time.sleep(0.01)
        stream.publish_orientation((1.0, 0.0, 0.0, 0.0), 0)
        time.sleep(0.1)
        a = math.radians(30.0)
        while not stop.is_set():
            stream.publish_orientation((math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)), 1)
            time.sleep(0.01)

    t = threading.Thread(target=sphere, daemon=True)
    t.start()
    chromium = HeadlessChromium(f"http://127.0.0.1:{stream.port}/", tmp_path / "profile")
    try:
        deadline = time.monotonic() + 40
        while time.monotonic() < deadline and chromium.text("quat") != "0.966 0.000 0.000 0.259":
            time.sleep(0.1)
        status, mode, count = chromium.text("status"), chromium.text("mode"), chromium.text("count")
        quat, turn = chromium.text("quat"), chromium.text("turn")
        shot = tmp_path / "page.png"
        chromium.screenshot(shot)
    finally:
        chromium.close()
        stop.set()
        t.join(2)
        stream.stop()
    assert status == "connected"
    assert mode == "3d"
    assert int(count) >= 2
    assert quat == "0.966 0.000 0.000 0.259"
    assert float(turn) == pytest.approx(30.0, abs=0.2)
    assert shot.stat().st_size > 5000  # a drawn object, not a blank page


def _pixels(path):
    from PIL import Image

    import numpy as np

    return np.asarray(Image.open(path).convert("RGB")).astype(int)


def _centroid(img, mask):
    import numpy as np

    ys, xs = np.nonzero(mask)
    assert len(xs) > 30, "colour not found in the screenshot"
    return xs.mean(), ys.mean()


def _red(img):
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return (r > 150) & (r - g > 70) & (r - b > 70)  # the x arrow, also where seen through the shell


def _shell(img):
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return (r > 120) & (g > 115) & (b > 95) & (abs(r - g) < 40)  # the light grey-beige shell


def test_three_js_scene_turns_and_moves_with_the_stream(tmp_path):
    """three.js from the package (WebGL): the x axis (red arrow) swings left when the sphere turns 40° left
    about the vertical, and the sphere moves right on screen when the pose source says it moved 10 cm to
    the right (west is the sphere's y: right is -y)."""
    stream = OrientationStream("127.0.0.1", 0, rate_hz=60)
    stream.mode = "3d"
    stream.start()
    pose = {"q": (1.0, 0.0, 0.0, 0.0), "p": [0.0, 0.0, 0.0]}
    stop = threading.Event()

    def sphere():
        while not stream.clients and not stop.is_set():
            time.sleep(0.01)
        while not stop.is_set():
            stream.position = list(pose["p"])
            stream.publish_orientation(pose["q"], 0)
            time.sleep(0.01)

    t = threading.Thread(target=sphere, daemon=True)
    t.start()
    chromium = HeadlessChromium(f"http://127.0.0.1:{stream.port}/", tmp_path / "profile")

    def settle(quat_text, position_text=None):
        deadline = time.monotonic() + 40
        while time.monotonic() < deadline:
            if chromium.text("quat") == quat_text and (position_text is None or chromium.text("position") == position_text):
                time.sleep(0.3)
                return
            time.sleep(0.1)
        pytest.fail(f"the page never showed {quat_text} / {position_text}: {chromium.text('quat')} {chromium.text('position')}")

    try:
        settle("1.000 0.000 0.000 0.000")
        renderer = chromium.text("renderer")
        chromium.screenshot(tmp_path / "ahead.png")
        a = math.radians(40.0)
        pose["q"] = (math.cos(a / 2), 0.0, 0.0, math.sin(a / 2))
        settle("0.940 0.000 0.000 0.342")
        chromium.screenshot(tmp_path / "left.png")
        pose["q"] = (1.0, 0.0, 0.0, 0.0)
        pose["p"] = [0.0, -0.10, 0.0]
        settle("1.000 0.000 0.000 0.000", "0.000 -0.100 0.000 m")
        chromium.screenshot(tmp_path / "moved.png")
    finally:
        chromium.close()
        stop.set()
        t.join(2)
        stream.stop()
    assert renderer == "three.js r170 (WebGL)", renderer
    ahead, left, moved = (_pixels(tmp_path / f"{n}.png") for n in ("ahead", "left", "moved"))
    assert _red(ahead).sum() > 100  # the x arrow is drawn, lit, in red
    assert _centroid(left, _red(left))[0] < _centroid(ahead, _red(ahead))[0] - 20
    x0, y0 = _centroid(ahead, _shell(ahead))
    x1, y1 = _centroid(moved, _shell(moved))
    assert x1 > x0 + 40 and abs(y1 - y0) < 25, ((x0, y0), (x1, y1))


def test_static_files_are_served_from_the_package():
    from sphere.daemon.page import static_response

    body, kind = static_response("/static/three.module.min.js")
    assert kind.startswith("text/javascript") and 'const t="170"' in body[:400]
    assert static_response("/static/../page.py") is None and static_response("/static/nope.js") is None
    stream = OrientationStream("127.0.0.1", 0)
    stream.start()
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{stream.port}/static/three.module.min.js", timeout=10) as r:
            assert r.headers["Content-Type"].startswith("text/javascript") and len(r.read()) > 500_000
    finally:
        stream.stop()
