"""Issue 30: the AR view of the 3-D page in headless Chromium. A rendered trial with known truth (a hand over a
third of the ball at 3-4 s, over all of it at 7-8 s) is replayed by sphere-mouse as a recorded session; the
page draws each camera frame with the virtual object where the hybrid tracker puts the ball, and the drawn
centre is compared with where the ball truly is in that frame."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
import urllib.request

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2", reason="opencv-python-headless (the camera extra) is part of the setup")
pytest.importorskip("websockets", reason="the 3-D stream needs websockets")

from sphere import broad  # noqa: E402

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="needs Chromium (apt-get install chromium)")


def _evaluate(port: int, expression: str):
    from websockets.sync.client import connect

    with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=5) as r:
        page = [p for p in json.load(r) if p.get("type") == "page"][0]
    with connect(page["webSocketDebuggerUrl"], max_size=None) as ws:
        ws.send(json.dumps({"id": 1, "method": "Runtime.evaluate",
                            "params": {"expression": expression, "returnByValue": True}}))
        while True:
            reply = json.loads(ws.recv(timeout=20))
            if reply.get("id") == 1:
                return reply.get("result", {}).get("result", {}).get("value")


def test_ar_overlay_stays_on_the_ball_through_an_occlusion(tmp_path):
    try:
        broad.trial_paths()
    except broad.BroadMissing as e:
        pytest.skip(f"BROAD trials are needed: {e}")
    from sphere.camera import trials

    rt = trials.rendered_trial("14", 64.0, 9.0, occlusions=trials.eval_occlusions(), jpeg_quality=85)
    session = tmp_path / "s"
    # the sphere runs 20 s before the camera's first frame: time for Chromium to open the page on a loaded machine
    trials.write_session(rt, session, lead_s=20.0)
    daemon = subprocess.Popen([sys.executable, "-m", "sphere.mouse", "--replay", str(session), "--speed", "1",
                               "--backend", "log", "--stream-port", "0", "--quiet"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                              env={**os.environ, "HOME": str(tmp_path)})
    browser = None
    try:
        port = None
        while port is None:
            line = daemon.stderr.readline()
            assert line, "sphere-mouse ended before serving the 3-D page"
            m = re.search(r"http://[\d.]+:(\d+)/", line)
            port = int(m.group(1)) if m else None
        profile = tmp_path / "profile"
        browser = subprocess.Popen([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu",
                                    "--disable-background-networking", "--disable-component-update", "--no-first-run",
                                    f"--user-data-dir={profile}", "--remote-debugging-port=0", "--window-size=1280,800",
                                    f"http://127.0.0.1:{port}/?ar=1"],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        port_file = profile / "DevToolsActivePort"
        deadline = time.monotonic() + 120
        while not port_file.exists() or not port_file.read_text().strip():
            assert time.monotonic() < deadline, "Chromium did not open its DevTools port"
            time.sleep(0.1)
        devtools = int(port_file.read_text().split()[0])
        daemon.wait(timeout=300)  # the replay ends with the session
        n, log = -1, []
        while len(log) != n:  # the page may still be drawing the last frames it received
            n = len(log)
            time.sleep(2.0)
            log = _evaluate(devtools, "window.arLog") or []
        diag = _evaluate(devtools, "document.getElementById('cameradiag').textContent")
    finally:
        for p in (browser, daemon):
            if p is not None and p.poll() is None:
                p.terminate()
                p.wait(timeout=20)
    assert log, f"the page drew no camera frame (the page's camera line: {diag!r})"
    assert "frames with the ball" in diag
    cam = rt.scene.camera
    _, mid, _, _ = rt.frame_times()
    rows = []
    for e in log:
        truth = cam.project(rt.truth_cam(mid[e["index"]])[None])[0]
        err = np.inf if e["centre"] is None else float(np.linalg.norm(np.subtract(e["centre"], truth)))
        rows.append((mid[e["index"]], err, e["outline"] is not None))
    t, err, outline = (np.array(c) for c in zip(*rows))
    hidden = (t >= 7.0) & (t < 8.0)
    # a page busy decoding skips frames (on this loaded machine about half); every one drawn is judged
    assert len(t) >= 0.3 * len(mid), f"only {len(t)} of {len(mid)} frames drawn"
    # the camera has lost the ball: no outline there. Of the second's 30 frames a page on an idle machine draws
    # most; at load 5-6 (a full test run beside other work) 4 were drawn: enough to judge the median and the worst
    assert hidden.sum() >= 4 and not outline[hidden].any()
    print(f"{len(t)} frames drawn, {(err <= 3.0).mean():.3f} within 3 px; in the occlusion {hidden.sum()}, "
          f"{(err[hidden] <= 3.0).mean():.3f}; worst {err.max():.2f} px")
    assert (err <= 3.0).mean() >= 0.95, f"{(err <= 3.0).mean():.3f} of the frames within 3 px"
    # the object stays on the ball from the IMU alone (every frame, without the browser: 27 of 30 within 3 px,
    # the last ones of the second drifting to 3.7 px; which of them a busy page draws varies)
    assert np.median(err[hidden]) <= 3.0 and err[hidden].max() <= 8.0
