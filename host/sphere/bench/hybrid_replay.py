"""The hybrid tracker as a user runs it: `sphere-mouse --replay SESSION` of rendered trials, the ``position``
read from the WebSocket, side by side with `sphere hybrid-eval`'s figures for the same trials.

Each trial is rendered as hybrid-eval renders it (the same camera, clutter, JPEG coding, capture latency, a
hand over a third of the ball at 3-4 s and over all of it at 7-8 s). hybrid-eval's tracker runs on it in
this process; then the trial is written as a recorded session (:func:`sphere.camera.trials.write_session`:
RAW_SAMPLE bytes as the sphere sends them from the trial's start, as hybrid-eval's host filter runs, and
the frames, each at its arrival time) and `sphere-mouse --replay SESSION --speed S` runs as a separate
process with the default
config (its own host orientation filter, the camera from the session, the stream's default position
smoothing). Every ``orientation`` message with a position is scored against where the ball is at the
moment of the output (the sample's arrival), with the same figures as hybrid-eval (after the camera's
alignment is known — the stream's ``camera.alignment`` — and outside the 1 s loss). Ratio = daemon /
hybrid-eval; the issue's target is ≤ 1.3.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from sphere import argtypes
from sphere.camera import evaluation as ev
from sphere.camera import trials
from sphere.camera.trials import SESSION_IMU_LATENCY_S
from sphere.commands.hybrid_eval import DEFAULT_TRIALS, refused

HELP = "sphere-mouse --replay of rendered sessions (position from the WebSocket) vs sphere hybrid-eval, as ratios"

TARGET_RATIO = 1.3
FIELDS = ("rmse_lateral_m", "rmse_depth_m", "jitter_lateral_m", "jitter_depth_m")


def add_arguments(p) -> None:
    p.add_argument("--trials", type=argtypes.stretches, default=DEFAULT_TRIALS, help=f"trial:start_s stretches (default {DEFAULT_TRIALS}, hybrid-eval's)")
    p.add_argument("--seconds", type=argtypes.seconds, default=12.0, help="length of each stretch (default 12, at least 9)")
    p.add_argument("--speed", type=argtypes.non_negative, default=0.0,
                   help="replay speed (default 0 = as fast as possible; 1 = as recorded: the same positions, each "
                        "session holding the trial from its start)")
    p.add_argument("--keep", metavar="DIR", help="keep the sessions in DIR (default: a temporary folder)")
    p.add_argument("--json", metavar="OUT", type=argtypes.out_file, help="write the figures as JSON")


def replay(session, speed: float, home, extra_args=(), types=("orientation",), host_dir=None) -> list[dict]:
    """Every message of those ``types`` of `sphere-mouse --replay SESSION` on its WebSocket, until it ends (with
    "frame" among them, the client subscribes to the camera's frames as the page's AR view does). ``host_dir``: the
    ``host/`` folder of another revision whose sphere-mouse runs (``--against``), else this tree's."""
    from websockets.asyncio.client import connect  # optional: websockets (the daemon extra)

    env = {**os.environ, "HOME": str(home)}
    python = [sys.executable]
    if host_dir is not None:  # -P: that tree's package, never one in the current folder
        env["PYTHONPATH"] = str(host_dir)
        python.append("-P")
    proc = subprocess.Popen([*python, "-m", "sphere.mouse", "--replay", str(session), "--speed", f"{speed:g}",
                             "--backend", "log", "--stream-port", "0", "--quiet", *extra_args],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
    try:
        port = None
        lines = []
        while port is None:
            line = proc.stderr.readline()
            if not line:
                raise RuntimeError("sphere-mouse ended before serving the 3-D stream: " + " ".join(lines)[-500:])
            lines.append(line.strip())
            m = re.search(r"ws://[\d.]+:(\d+)/ws", line)
            port = int(m.group(1)) if m else None

        async def receive():
            got = []
            async with connect(f"ws://127.0.0.1:{port}/ws", max_size=None) as ws:
                if "frame" in types:
                    await ws.send(json.dumps({"subscribe": "frames"}))
                while True:
                    try:
                        msg = json.loads(await asyncio.wait_for(ws.recv(), 30))
                    except Exception:
                        return got  # the replay ended and the daemon closed the stream
                    if msg.get("type") in types:
                        got.append(msg)

        return asyncio.run(receive())
    finally:
        if proc.poll() is None:
            proc.terminate()
        proc.wait(timeout=30)


def score_messages(messages, rt, lead_s: float, hybrid_eval_run):
    """hybrid-eval's figures for the daemon's positions (the messages' device times mapped to the stretch)."""
    rows = [(m["t_us"] * 1e-6 - 1.0 - lead_s + SESSION_IMU_LATENCY_S, m["position"], m.get("camera") or {})
            for m in messages if m.get("t_us") is not None]
    rows = [r for r in rows if 0.0 <= r[0] <= rt.duration_s]
    t = np.array([r[0] for r in rows])
    est = np.array([r[1] if r[1] is not None else [np.nan] * 3 for r in rows], float)
    ready = [r[0] for r in rows if r[2].get("alignment")]
    mov = rt.trial.movement.astype(bool)
    rest = ~mov[np.clip(np.searchsorted(rt.t, t - SESSION_IMU_LATENCY_S), 0, len(mov) - 1)]
    run = SimpleNamespace(t_out=t, truth=rt.truth_cam(t), rest=rest, losses=hybrid_eval_run.losses,
                          alignment_ready_s=ready[0] if ready else None)
    fig = ev.method_figures(run, rt, est)
    fig["messages"] = len(rows)
    fig["alignment_ready_s"] = run.alignment_ready_s
    fig["camera"] = rows[-1][2] if rows else {}
    return fig


def run(args) -> int:
    stretches = args.trials
    code = refused("sphere bench hybrid-replay", args.seconds, [n for n, _ in stretches])
    if code is not None:
        return code

    occl = trials.eval_occlusions()
    tmp = tempfile.TemporaryDirectory(prefix="sphere-hybrid-replay-")
    folder = Path(args.keep) if args.keep else Path(tmp.name)
    doc = {"speed": args.speed, "seconds": args.seconds, "target_ratio": TARGET_RATIO, "trials": {}}
    head = f"{'':26}{'lat mm':>8}{'dep mm':>8}{'jit lat':>8}{'jit dep':>8}{'lag ms':>8}{'return mm':>10}"
    print(f"sphere-mouse --replay SESSION --speed {args.speed:g} (default config), position from the WebSocket, "
          f"against sphere hybrid-eval on the same stretches")
    worst = 0.0
    try:
        for name, start in stretches:
            try:
                rt = trials.rendered_trial(name, start, args.seconds, occlusions=occl, jpeg_quality=85)
            except ValueError as e:
                print(f"sphere bench hybrid-replay: {e}", file=sys.stderr)
                return 2
            r = ev.run(rt)
            evf = ev.method_figures(r, rt, r.est["hybrid"])
            session = folder / f"{rt.name}-{start:g}"
            if session.exists():
                shutil.rmtree(session)
            bases = trials.write_session(rt, session)
            messages = replay(session, args.speed, folder)
            dmf = score_messages(messages, rt, bases["lead_s"], r)
            ratios = {k: dmf[k] / evf[k] for k in FIELDS if dmf.get(k) and evf.get(k)}
            worst = max([worst, *(v for k, v in ratios.items() if k.startswith("rmse"))])
            doc["trials"][rt.name] = {"start_s": start, "hybrid_eval": evf, "daemon": dmf, "ratios": ratios}
            print(f"\n{rt.name} ({dmf['messages']} messages; alignment at {dmf['alignment_ready_s']} s; "
                  f"camera {dmf['camera']})")
            print(head)
            for label, f in (("hybrid-eval", evf), ("sphere-mouse --replay", dmf)):
                print(f"{label:26}{_row(f)}")
            print(f"{'ratio':26}" + "".join(f"{ratios[k]:>8.2f}" if k in ratios else f"{'–':>8}" for k in FIELDS))
    finally:
        tmp.cleanup()
    mean = {}
    for k in FIELDS:
        pairs = [(t["daemon"][k], t["hybrid_eval"][k]) for t in doc["trials"].values()
                 if t["daemon"].get(k) and t["hybrid_eval"].get(k)]
        if pairs:
            mean[k] = (float(np.mean([a for a, _ in pairs])), float(np.mean([b for _, b in pairs])))
    doc["mean"] = mean
    print("\nmean over the stretches: " + ", ".join(f"{k.replace('_m', '')} {1000 * a:.2f} / {1000 * b:.2f} mm "
                                                   f"(×{a / b:.2f})" for k, (a, b) in mean.items()))
    state = "met" if worst <= TARGET_RATIO else "MISSED"
    print(f"target: every stretch's RMSE within {TARGET_RATIO}× hybrid-eval's: {state} (worst ×{worst:.2f})")
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=2, default=float))
        print(f"wrote {args.json}", file=sys.stderr)
    return 0


def _row(f) -> str:
    def cell(v, scale, w=8):
        return f"{v * scale:>{w}.1f}" if isinstance(v, (int, float)) else f"{'–':>{w}}"

    loss = (f.get("losses") or [{}])[0].get("error_at_return_m")
    return (cell(f.get("rmse_lateral_m"), 1000) + cell(f.get("rmse_depth_m"), 1000) + cell(f.get("jitter_lateral_m"), 1000)
            + cell(f.get("jitter_depth_m"), 1000) + cell(f.get("latency_ms"), 1) + cell(loss, 1000, 10))
