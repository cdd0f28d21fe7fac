"""Every smoothing filter of the registry drives the real X pointer (sphere-mouse --backend x11 on Xvfb,
replayed captures), a sphere held in the air is measured from the X pointer itself (sampled at ~1 kHz), and
the 3-D stream's pose is measured from the stream's own WebSocket messages."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from sphere.bench._xvfb import PointerSampler
from sphere.bench.drift import anchored_times, daemon_path, on_grid
from sphere.daemon.scripted_sphere import hello_packet, script_bytes
from sphere.protocol import encode_frame
from sphere.smoothing.registry import FILTERS
from test_mouse_x11 import pointer, pytestmark, run_mouse, xdotool, xvfb  # noqa: F401  (the Xvfb fixture)

PX_PER_DEG = 1920 / 40.0  # the scale: 40° per 1920 px (--set output.screen_width_px=1920)


def hold_capture(path, script, seed=3, params=None):
    """A replayable capture of synthetic:hold with this script (HELLO, then RAW_SAMPLE at 200 Hz)."""
    from sphere.sim.trace import raw_packets
    from sphere.sim.hold import hold_script

    h = hold_script(sum(step[1] for step in script), seed, params, script=script)
    frames = [encode_frame(hello_packet(), 0)]
    frames += [encode_frame(p, (i + 1) & 0xFF) for i, (_, p) in enumerate(raw_packets(h.motion))]
    path.write_bytes(b"".join(frames))
    return h


@pytest.mark.parametrize("name", list(FILTERS))
def test_every_registry_filter_drives_the_x_pointer(xvfb, tmp_path, name):
    """A 5° turn left ends 160 px left (1280 px per 40°) with every filter: it moves, it settles, it is exact."""
    capture = tmp_path / "turn.bin"
    capture.write_bytes(script_bytes([("still", 1.0), ("turn", (0, 0, 1), 10.0, 0.5), ("still", 0.6)]))
    xdotool(xvfb, "mousemove", "640", "512")
    r = run_mouse(xvfb, capture, "--speed", "0", "--set", f"pointer.smoothing={name}")
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    x, y = pointer(xvfb)
    assert abs(x - (640 - 160)) <= 2 and abs(y - 512) <= 2, (name, x, y)


def test_the_x_pointer_shows_the_pixel_nearer_the_motion(xvfb, tmp_path):
    """A turn whose end lies 0.85–0.97 px past a whole pixel (where the daemon's own path puts it with its sub-pixel
    remainder, `sphere.bench.drift.daemon_path` on the same capture): the X pointer ends on the nearer pixel with the
    default `step_at_px` (0.8), one pixel short of it with whole pixels only (`step_at_px=1`, as before)."""
    from sphere.bench.drift import daemon_path

    for centideg in range(500, 560):  # a 10 °/s turn of 5.00–5.59° to the left: 240–268 px at 48 px/°
        script = [("still", 1.0), ("turn", (0, 0, 1), 10.0, centideg / 1000.0), ("still", 0.6)]
        end = -float(daemon_path(script_bytes(script))[-1, 3])  # px to the left, with the sub-pixel remainder
        if 0.85 <= end - math.floor(end) <= 0.97:
            break
    else:
        pytest.fail("no turn of 5.00-5.59 degrees ends 0.85-0.97 px past a pixel")
    capture = tmp_path / "turn.bin"
    capture.write_bytes(script_bytes(script))
    ends = {}
    for extra in ((), ("--set", "pointer.step_at_px=1")):
        xdotool(xvfb, "mousemove", "640", "512")
        r = run_mouse(xvfb, capture, "--speed", "0", "--set", "output.screen_width_px=1920", *extra)
        assert r.returncode == 0, r.stderr
        ends[extra] = pointer(xvfb)
    print(f"a {centideg / 100:.2f}° turn: the daemon's path {end:.2f} px left; the X pointer "
          f"{640 - ends[()][0]} px left (default), {640 - ends[extra][0]} px (step_at_px=1)")
    assert ends[()] == (640 - math.ceil(end), 512)
    assert ends[extra] == (640 - math.floor(end), 512)


@pytest.mark.parametrize("setting, says", [
    ("pointer.smoothing=kalmann", "[pointer] smoothing = 'kalmann': must be one of 'none', 'tremor'"),
    ("stream.smoothing=wobble", "[stream] smoothing = 'wobble': must be one of"),
    ("smoothing.tremor.notch_q=0", "[smoothing.tremor] notch_q = 0: must be between 0.1 and 20"),
    ("smoothing.tremor.notch_qq=1", "unknown key [smoothing.tremor] notch_qq"),
])
def test_bad_smoothing_settings_are_one_clear_line(xvfb, tmp_path, setting, says):
    capture = tmp_path / "s.bin"
    capture.write_bytes(script_bytes([("still", 0.2)]))
    r = run_mouse(xvfb, capture, "--speed", "0", "--set", setting)
    assert r.returncode == 2, r.stderr
    assert says in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr


#: rest on the table (the bias is learnt), picked up and held still, a fine 3 °/s aiming turn, held, a fast turn
HELD = [("rest", 3.0, "", 0.0, ""), ("held", 5.5, "", 0.0, ""), ("turn", 1.0, "fine", -3.0, "yaw"),
        ("held", 2.0, "", 0.0, ""), ("turn", 0.1, "fast", -120.0, "yaw"), ("held", 1.5, "", 0.0, "")]


def _window_mean(t, x, a, b):
    """The mean of the X pointer over [a, b) as a step function (it stays where the last read found it): a gap in
    the reads (the sampler waiting on a loaded machine's X server) leaves the window's mean defined."""
    grid = np.arange(a, b, 0.001)
    k = np.searchsorted(t, grid, side="right") - 1
    assert k[0] >= 0, "the X trace starts after the window"
    return float(x[k].mean())


def _half_travel_s(t, x, start_s, end_s):
    """When x first gets half way between its means over 0.25 s before start_s and 0.4 s from end_s + 0.5 s."""
    pre = _window_mean(t, x, start_s - 0.3, start_s - 0.05)
    post = _window_mean(t, x, end_s + 0.5, end_s + 0.9)
    level = pre + 0.5 * (post - pre)
    after = (t >= start_s - 0.05) & (np.sign(post - pre) * (x - level) >= 0)
    return float(t[after][0]), post - pre


def test_held_in_the_air_tremor_jitter_from_the_x_pointer(xvfb, tmp_path):
    """Issue 20's targets through X: held still, the tremor jitter (RMS about a line over 1-s windows) is
    ≤ 1.5 px at 40° per 1920 px (≈ 7 px unfiltered), and the fine 3 °/s turn reaches half its travel no more
    than 40 ms later than the fast one (each against the motion's own timeline)."""
    capture = tmp_path / "held.bin"
    h = hold_capture(capture, HELD)
    xdotool(xvfb, "mousemove", "100", "500")
    with PointerSampler(xvfb, recentre=False) as s:
        r = run_mouse(xvfb, capture, "--speed", "1", "--set", "output.screen_width_px=1920", timeout=120)
    assert r.returncode == 0, r.stderr
    a = np.array(s.samples)
    t, x, y = a[:, 0] - a[0, 0], a[:, 1], a[:, 2]
    # the motion's time in the X trace: the fast turn (12° = 576 px right, nothing else comes near) is taken
    # as reaching half its travel at its own half time; the fine turn's lag is then measured against it
    fine, fast = [p for p in h.phases if p.kind == "turn"]
    level = x[-1] - 0.5 * 12.0 * PX_PER_DEG
    t0 = t[np.flatnonzero(x >= level)[0]] - 0.5 * (fast.start_s + fast.end_s)
    held = [p for p in h.phases if p.kind == "held"][0]
    sq, n = 0.0, 0
    for w0 in np.arange(held.start_s + 0.8, held.end_s - 1.0, 1.0):
        m = (t >= t0 + w0) & (t < t0 + w0 + 1.0)
        tt = t[m]
        for v in (x[m], y[m]):
            resid = v - np.polyval(np.polyfit(tt, v, 1), tt)
            sq += float(np.sum(resid * resid))
        n += int(m.sum())
    jitter = math.sqrt(sq / n)
    print(f"held tremor jitter from the X pointer: {jitter:.2f} px RMS over {n} samples")
    assert jitter <= 1.5
    tf, travel_f = _half_travel_s(t - t0, x, fine.start_s, fine.end_s)
    tq, travel_q = _half_travel_s(t - t0, x, fast.start_s, fast.end_s)
    lag_fine = (tf - 0.5 * (fine.start_s + fine.end_s)) * 1000
    lag_fast = (tq - 0.5 * (fast.start_s + fast.end_s)) * 1000
    print(f"half travel: fine 3 °/s {lag_fine:.1f} ms, fast 120 °/s {lag_fast:.1f} ms after the motion's")
    assert abs(travel_f - 3.0 * PX_PER_DEG) <= 0.05 * 3.0 * PX_PER_DEG  # 144 px ± 5 %
    assert lag_fine - lag_fast <= 40.0


def test_stream_pose_jitter_from_the_websocket(tmp_path):
    """The 3-D stream's own messages: orientation jitter ≤ 0.05° lying still and ≤ 0.1° held in the air."""
    from websockets.sync.client import connect

    from sphere.quaternion import conj, mul
    from sphere.smoothing.pose import log_deg

    capture = tmp_path / "held.bin"
    hold_capture(capture, [("rest", 4.5, "", 0.0, ""), ("held", 4.0, "", 0.0, "")])
    proc = subprocess.Popen(
        [sys.executable, "-m", "sphere.mouse", "--replay", str(capture), "--speed", "1", "--backend", "log",
         "--stream-port", "0", "--config", os.devnull], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    try:
        port = None
        for line in proc.stderr:
            if "WebSocket ws://" in line:
                port = int(line.rsplit(":", 1)[1].split("/")[0])
                break
        assert port, "no stream"
        messages = []
        with connect(f"ws://127.0.0.1:{port}/ws", origin=f"http://127.0.0.1:{port}") as ws:
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                try:
                    m = json.loads(ws.recv(timeout=2))
                except TimeoutError:
                    break
                except Exception:
                    break
                if m.get("type") == "orientation":
                    messages.append((m["t_us"], m["quat"]))
    finally:
        proc.wait(30)
    assert len(messages) > 100, len(messages)
    t = np.array([m[0] for m in messages], dtype=float) * 1e-6 - 1.0  # raw_packets start at 1 s device time
    q0 = messages[0][1]
    r = np.array([log_deg(mul(q, conj(q0))) for _, q in messages])

    def jitter(a, b):
        sq, n = 0.0, 0
        for w0 in np.arange(a, b - 1.0 + 1e-9, 1.0):
            m = (t >= w0) & (t < w0 + 1.0)
            for k in range(3):
                resid = r[m, k] - np.polyval(np.polyfit(t[m], r[m, k], 1), t[m])
                sq += float(np.sum(resid * resid))
            n += int(m.sum())
        return math.sqrt(sq / n)

    still, held = jitter(1.5, 4.5), jitter(5.1, 8.4)
    print(f"stream orientation jitter: still {still:.4f}°, held {held:.4f}° RMS ({len(messages)} messages)")
    assert still <= 0.05 and held <= 0.1


#: a sphere turned steadily (no tremor, no wander: a turntable) at 10–150 °/s with sharp stops, between rests
CLEAN_TURNS = [("rest", 3.0, "", 0.0, ""), ("turn", 1.0, "slow", -10.0, "yaw"), ("rest", 1.5, "", 0.0, ""),
               ("turn", 0.25, "medium", 40.0, "yaw"), ("rest", 1.5, "", 0.0, ""),
               ("turn", 0.1, "fast", -150.0, "yaw"), ("rest", 1.5, "", 0.0, ""),
               ("turn", 0.15, "medium", 80.0, "yaw"), ("rest", 1.5, "", 0.0, ""),
               ("turn", 0.5, "slow", 20.0, "pitch"), ("rest", 1.5, "", 0.0, ""),
               ("turn", 0.1, "fast", -100.0, "pitch"), ("rest", 1.5, "", 0.0, ""),
               ("turn", 1.0, "fine", 3.0, "yaw"), ("rest", 1.5, "", 0.0, "")]  # and slow aiming: 3 °/s for 1 s


def test_steady_turns_travel_overshoot_drift_from_the_x_pointer(xvfb, tmp_path):
    """Issue 20's targets for a sphere lying still and turning at 10–150 °/s, read from the X pointer (replayed
    at 2× speed, pointer sampled at up to ~1 kHz): median travel within 1 % and every turn within 3 %, overshoot
    ≤ 1 px and drift ≤ 1 px/s after every stop, jitter lying still ≤ 0.3 px; after the 1-s turn at 3 °/s
    (slow aiming, once learnt as gyro bias): travel within 5 % and drift ≤ 1 px/s."""
    from sphere.sim.hold import with_params

    capture = tmp_path / "turns.bin"
    h = hold_capture(capture, CLEAN_TURNS, 4, with_params(tremor_rms_deg=0.0, wander_rms_deg=0.0))
    speed = 2.0
    xdotool(xvfb, "mousemove", "160", "200")
    with PointerSampler(xvfb, recentre=False) as s:
        r = run_mouse(xvfb, capture, "--speed", str(speed), "--set", "output.screen_width_px=1920", timeout=120)
    assert r.returncode == 0, r.stderr
    a = np.array(s.samples, dtype=float)
    turns = [p for p in h.phases if p.kind == "turn"]
    # each X sample in device time, anchored at every step to the daemon's own path on the same capture: a
    # wall-clock mapping fixed at the first turn put the next turn's start into a held second (0.05 s before it)
    # when a loaded machine made the replay fall behind (jitter 0.39 px at load 7)
    ref = daemon_path(capture.read_bytes())
    path = np.column_stack([anchored_times(a, ref, speed) - ref[0, 0], a[:, 1:]])  # motion time = device − 1 s
    dev = np.arange(int(round(sum(step[1] for step in CLEAN_TURNS) * 200))) * 0.005
    xy = on_grid(path, dev[-1] + 0.005)
    rests = [(1.5, turns[0].start_s - 0.05)] + [(p.end_s + 0.45, p.end_s + 1.45) for p in turns]
    sq, n = 0.0, 0
    for a_s, b_s in rests:  # jitter lying still: RMS distance from a line fit over each rest
        m = (dev > a_s) & (dev < b_s)
        for k in range(2):
            resid = xy[m, k] - np.polyval(np.polyfit(dev[m], xy[m, k], 1), dev[m])
            sq += float(np.sum(resid * resid))
        n += int(m.sum())
    jitter = math.sqrt(sq / n)
    errors, overs, drifts = [], [], []
    for ph in turns:
        u = np.array([-np.sign(ph.rate_dps), 0.0]) if ph.axis == "yaw" else np.array([0.0, np.sign(ph.rate_dps)])
        pre = xy[(dev > ph.start_s - 0.5) & (dev < ph.start_s - 0.05)].mean(axis=0) @ u
        early = xy[(dev > ph.end_s + 0.4) & (dev < ph.end_s + 0.5)].mean(axis=0)
        late = xy[(dev > ph.end_s + 1.4) & (dev < ph.end_s + 1.5)].mean(axis=0)  # drift: over the second after 0.45 s
        travel = early @ u - pre
        truth = abs(ph.rate_dps) * (ph.end_s - ph.start_s) * PX_PER_DEG
        errors.append(abs(travel / truth - 1.0))
        overs.append(max(0.0, float((xy[(dev >= ph.end_s) & (dev < ph.end_s + 0.4)] @ u).max() - early @ u)))
        drifts.append(float(np.linalg.norm(late - early)))
    print(f"travel errors {[f'{e:.2%}' for e in errors]}, overshoot {overs} px, drift {[round(d, 2) for d in drifts]} px/s, "
          f"jitter at rest {jitter:.3f} px")
    assert jitter <= 0.3
    fine = [k for k, p in enumerate(turns) if p.band == "fine"]
    assert all(errors[k] <= 0.05 for k in fine)
    errors = [e for k, e in enumerate(errors) if k not in fine]
    assert np.median(errors) <= 0.01 and max(errors) <= 0.03
    assert max(overs) <= 1.0 and max(drifts) <= 1.0


@pytest.mark.slow
def test_held_in_the_air_through_the_real_firmware(xvfb, tmp_path):
    """The whole chain as the issue tried it: synthetic:hold through the chip models into the real firmware on
    the virtual board, its capture replayed by sphere-mouse onto Xvfb, the X pointer sampled at ~1 kHz:
    the tremor jitter held in the air is ≤ 1.5 px RMS at 40° per 1920 px."""
    from simscenarios import _run, need_board, need_firmware

    from sphere.sim.hold import hold_script

    need_board()
    elf = need_firmware()
    script = [("rest", 3.0, "", 0.0, ""), ("held", 4.5, "", 0.0, "")]
    h = hold_script(7.5, 5, script=script)
    run = _run("hold", elf, h.motion, 7.5)
    assert run.returncode == 0 and run.capture, run.stderr
    capture = tmp_path / "hold.bin"
    capture.write_bytes(run.capture)
    xdotool(xvfb, "mousemove", "640", "512")
    with PointerSampler(xvfb, recentre=False) as s:
        r = run_mouse(xvfb, capture, "--speed", "1", "--set", "output.screen_width_px=1920", timeout=120)
    assert r.returncode == 0, r.stderr
    a = np.array(s.samples, dtype=float)
    t, xy = a[:, 0], a[:, 1:]
    moved = np.flatnonzero(np.abs(xy - xy[0]).max(axis=1) >= 2)
    assert len(moved), "the pointer never moved"
    picked_up = t[moved[0]]  # the hand's motion fades in at 3.0 s of the motion: the first pixel follows it
    sq, n = 0.0, 0
    for w0 in (0.8, 1.8, 2.8):  # three 1-s windows inside the 4.5 s held
        m = (t >= picked_up + w0) & (t < picked_up + w0 + 1.0)
        for k in range(2):
            resid = xy[m, k] - np.polyval(np.polyfit(t[m], xy[m, k], 1), t[m])
            sq += float(np.sum(resid * resid))
        n += int(m.sum())
    jitter = math.sqrt(sq / n)
    print(f"held tremor jitter through the firmware and the X pointer: {jitter:.2f} px RMS over {n} samples")
    assert jitter <= 1.5
