"""The 3-D stream: the WebSocket's JSON messages and the page over HTTP, on 127.0.0.1."""

from __future__ import annotations

import asyncio
import json
import threading
import time
import urllib.error
import urllib.request

import pytest

pytest.importorskip("websockets", reason="the 3-D stream needs websockets (pip install websockets)")

from sphere.daemon.app import SphereMouse  # noqa: E402
from sphere.daemon.backends.memory import RecordingBackend  # noqa: E402
from sphere.daemon.config import Config  # noqa: E402
from sphere.daemon.sources import ReplaySource  # noqa: E402
from sphere.daemon.stream3d import OrientationStream  # noqa: E402
from sphere.daemon.scripted_sphere import script_bytes  # noqa: E402


@pytest.fixture
def stream():
    s = OrientationStream("127.0.0.1", 0, rate_hz=100)
    s.start()
    yield s
    s.stop()


def collect(port, action, until, timeout=5.0):
    """Connect, run action(), return the messages received until until(messages) is true."""
    from websockets.asyncio.client import connect

    async def go():
        got = []
        async with connect(f"ws://127.0.0.1:{port}/ws") as ws:
            action()
            deadline = time.monotonic() + timeout
            while not until(got) and time.monotonic() < deadline:
                try:
                    got.append(json.loads(await asyncio.wait_for(ws.recv(), 0.5)))
                except asyncio.TimeoutError:
                    pass
        return got

    return asyncio.run(go())


def test_messages(stream):
    stream.mode = "3d"

    def act():
        time.sleep(0.05)
        stream.publish_orientation((0.5, 0.5, -0.5, 0.5), 1234)
        stream.publish_event("single_tap", 1300)

    msgs = collect(stream.port, act, lambda m: len(m) >= 3)
    assert msgs[0] == {"type": "mode", "mode": "3d"}
    assert {"type": "event", "event": "single_tap", "t_us": 1300} in msgs
    ori = [m for m in msgs if m["type"] == "orientation"][0]
    assert ori == {"type": "orientation", "t_us": 1234, "quat": [0.5, 0.5, -0.5, 0.5], "frame": "NWU",
                   "mode": "3d", "position": None, "camera": None}


def test_rate_limit_and_only_changes(stream):
    stream.rate_hz = 100

    def act():
        for i in range(300):  # 300 updates in ~0.3 s at 100 messages/s at most
            stream.publish_orientation((1.0, 0.0, 0.0, 0.0), i)
            time.sleep(0.001)

    msgs = collect(stream.port, act, lambda m: False, timeout=0.6)
    n = len([m for m in msgs if m["type"] == "orientation"])
    assert 1 <= n <= 60


def test_page_and_404_over_http(stream):
    with urllib.request.urlopen(f"http://127.0.0.1:{stream.port}/", timeout=5) as page:
        assert page.headers["Content-Type"].startswith("text/html")
        body = page.read().decode()
    assert "new WebSocket" in body and 'id="quat"' in body
    with pytest.raises(urllib.error.HTTPError) as e:
        urllib.request.urlopen(f"http://127.0.0.1:{stream.port}/nope", timeout=5)
    assert e.value.code == 404


def test_daemon_streams_orientation_in_3d_mode(tmp_path, stream):
    cap = tmp_path / "c.bin"
    cap.write_bytes(script_bytes([("still", 0.5), ("turn", (0, 0, 1), 90.0, 1.0), ("still", 0.3), ("tap", "double_tap"),
                                  ("still", 0.3)]))
    cfg = Config().with_overrides({"mode": {"start": "3d"}}, "test")
    backend = RecordingBackend()
    daemon = SphereMouse(cfg, ReplaySource(cap, speed=2.0), backend, stream=stream, log=lambda m: None)
    t = threading.Thread(target=daemon.run)
    msgs = collect(stream.port, t.start, lambda m: any(x["type"] == "event" for x in m), timeout=8)
    t.join(10)
    oris = [m for m in msgs if m["type"] == "orientation"]
    assert len(oris) > 20
    from sphere.quaternion import angle_between_deg, conjugate, multiply

    first, last = oris[0]["quat"], oris[-1]["quat"]
    assert angle_between_deg(first, last) == pytest.approx(90.0, abs=4.0)  # the turn, whatever the start heading
    rel = multiply(conjugate(first), last)
    assert abs(rel[3]) > 0.68 and abs(rel[1]) < 0.05 and abs(rel[2]) < 0.05  # about the vertical
    assert {"type": "event", "event": "double_tap"} == {k: v for k, v in msgs[-1].items() if k != "t_us"}
    assert backend.moves == 0 and backend.clicks == []
