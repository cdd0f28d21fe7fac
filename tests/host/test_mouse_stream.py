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
from sphere.daemon.sources.replay import ReplaySource  # noqa: E402
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


def test_camera_frames_only_to_a_client_that_asks_for_them(stream):
    """The AR view's frames (issue 30): a JPEG with the pose drawn at its exposure, sent only to a client that
    sent {"subscribe": "frames"}; the daemon keeps frames only while one watches (frames_wanted)."""
    import base64

    import numpy as np

    cv2 = pytest.importorskip("cv2")
    from websockets.asyncio.client import connect

    image = np.zeros((48, 64, 3), np.uint8)
    image[10:20, 30:40] = (0, 200, 0)
    frame = {"index": 7, "image": image, "t_exposure_s": 1.0, "radius_m": 0.04, "position": [0.0, 0.0, 1.0],
             "rotation": None, "outline": {"centre": [35.0, 15.0], "radius": 5.0, "verdict": "accepted"},
             "camera": {"width": 64, "height": 48, "fx": 50.0, "fy": 50.0, "cx": 32.0, "cy": 24.0, "dist": [0] * 5}}

    async def go():
        async with connect(f"ws://127.0.0.1:{stream.port}/ws") as plain, \
                connect(f"ws://127.0.0.1:{stream.port}/ws") as watcher:
            assert not stream.frames_wanted
            await watcher.send(json.dumps({"subscribe": "frames"}))
            await plain.send("not json at all")  # ignored
            deadline = time.monotonic() + 5
            while not stream.frames_wanted and time.monotonic() < deadline:
                await asyncio.sleep(0.02)
            assert stream.frames_wanted
            stream.publish_frame(frame)
            got = json.loads(await asyncio.wait_for(watcher.recv(), 5))
            try:
                other = json.loads(await asyncio.wait_for(plain.recv(), 0.5))
            except asyncio.TimeoutError:
                other = None
            return got, other

    got, other = asyncio.run(go())
    assert other is None
    assert got["type"] == "frame" and got["index"] == 7 and got["outline"]["centre"] == [35.0, 15.0]
    img = cv2.imdecode(np.frombuffer(base64.b64decode(got["jpeg"]), np.uint8), cv2.IMREAD_COLOR)
    assert img.shape == (48, 64, 3) and img[15, 35, 1] > 150
    deadline = time.monotonic() + 5
    while stream.frames_wanted and time.monotonic() < deadline:  # the watcher left
        time.sleep(0.02)
    assert not stream.frames_wanted
