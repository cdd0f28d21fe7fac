"""The built-in 3-D page in headless Chromium: it connects to the WebSocket and turns with the sphere."""

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
            [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--remote-debugging-port=0",
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
