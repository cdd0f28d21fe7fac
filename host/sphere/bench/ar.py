"""The 3-D page's AR view as a user sees it, measured per stage: `sphere-mouse --replay SESSION` of rendered
trials, the camera's frames read from the WebSocket as the page reads them ({"subscribe": "frames"}), the
virtual object's centre projected as the page draws it (the pose's position through the camera's intrinsics
and lens distortion) and compared with where the ball truly is in that frame (the middle of its exposure).

Each trial is rendered as `sphere hybrid-eval` renders it (a hand over a third of the ball at 3-4 s, over all of
it at 7-8 s) and written as a recorded session with ``--lead`` seconds of the sphere before the camera's first
frame. Where an error comes from, per frame (pixels):

- **stamp**: the ball's true position at the time the daemon gives the frame's exposure, against the truth at
  the true exposure (what the frame's time stamp alone costs);
- **filter**: the drawn centre against the true position at the stamped time (the hybrid tracker's error at
  that moment: its lag at speed, its IMU coasting while the ball is hidden);
- **outline**: the detector's outline centre against the truth (when it found the ball).

The issue's target: the drawn centre within 3 px of the true centre in ≥ 95 % of the frames, the 1 s loss
included.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from sphere import argtypes
from sphere.bench.hybrid_replay import replay
from sphere.camera import trials
from sphere.commands.hybrid_eval import DEFAULT_TRIALS, refused

HELP = "the AR view's drawn centre vs the ball's true centre per stage (stamp, filter, outline), sphere-mouse --replay"

TARGET_PX = 3.0
TARGET_SHARE = 0.95
#: this tree's rows (beside another revision's with --against)
THIS = "this"


def add_arguments(p) -> None:
    p.add_argument("--trials", type=argtypes.stretches, default=DEFAULT_TRIALS, help=f"trial:start_s stretches (default {DEFAULT_TRIALS}, hybrid-eval's)")
    p.add_argument("--seconds", type=argtypes.seconds, default=12.0, help="length of each stretch (default 12, at least 9)")
    p.add_argument("--speed", type=argtypes.non_negative, default=1.0,
                   help="replay speed (default 1, as recorded: the page gets every frame; faster replays skip some)")
    p.add_argument("--lead", type=argtypes.seconds, default=5.0,
                   help="seconds of the sphere before the camera's first frame (default 5)")
    p.add_argument("--json", metavar="OUT", type=argtypes.out_file, help="write the figures as JSON")
    p.add_argument("--against", metavar="REV", help="also run every stretch with the sphere-mouse of this git revision "
                   "of the repository (its host/ from git archive), side by side in the same run")


def judge(messages, rt, lead_s: float) -> dict:
    """Per-stage errors (px) of the page's frame messages against the rendered truth."""
    cam = rt.scene.camera
    _, mid, _, _ = rt.frame_times()

    def px(p):
        return cam.project(np.atleast_2d(np.asarray(p, float)))[0]

    rows = []
    for m in messages:
        k = m.get("index")
        if k is None or not 0 <= k < len(mid):
            continue
        truth = px(rt.truth_cam(mid[k]))
        stamped = px(rt.truth_cam(m["t_exposure_s"] - lead_s))
        drawn = None if m.get("position") is None else px(m["position"])
        outline = m.get("outline")
        rows.append((mid[k], np.inf if drawn is None else float(np.linalg.norm(drawn - truth)),
                     float(np.linalg.norm(stamped - truth)),
                     np.inf if drawn is None else float(np.linalg.norm(drawn - stamped)),
                     np.nan if outline is None else float(np.linalg.norm(np.subtract(outline["centre"], truth)))))
    if not rows:
        return {"frames": 0, "of": len(mid)}
    t, total, stamp, filt, outl = (np.array(c) for c in zip(*rows))
    losses = [(o.t0, o.t1) for o in rt.scene.occlusions if o.cover >= 1.0]
    hidden = np.zeros(len(t), bool)
    for a, b in losses:
        hidden |= (t >= a) & (t < b)

    def share(x, m=None):
        x = x if m is None else x[m]
        return float(np.mean(x <= TARGET_PX)) if len(x) else None

    def stats(x):
        f = x[np.isfinite(x)]
        return {"within": share(x), "median_px": float(np.median(f)) if len(f) else None,
                "p95_px": float(np.percentile(f, 95)) if len(f) else None}

    return {"frames": len(t), "of": len(mid), "within": share(total), "within_seen": share(total, ~hidden),
            "within_loss": share(total, hidden), "loss_frames": int(hidden.sum()),
            "worst_loss_px": float(total[hidden].max()) if hidden.any() else None,
            "stages": {"drawn": stats(total), "stamp": stats(stamp), "filter": stats(filt), "outline": stats(outl)}}


def run(args) -> int:
    stretches = args.trials
    code = refused("sphere bench ar", args.seconds, [n for n, _ in stretches])
    if code is not None:
        return code
    tmp = tempfile.TemporaryDirectory(prefix="sphere-bench-ar-")
    folder = Path(tmp.name)
    sides = [(THIS, None)]
    if args.against:  # that revision's host/ first: a wrong name is a usage error before any work
        from sphere.bench._revision import RevisionError, tree_of  # --against only
        try:
            (folder / "against").mkdir()
            sides.append((args.against, tree_of(args.against, str(folder / "against"))))
        except RevisionError as e:
            tmp.cleanup()
            print(f"sphere bench ar: {e}", file=sys.stderr)
            return 2
    doc = {"speed": args.speed, "seconds": args.seconds, "lead_s": args.lead, "target_px": TARGET_PX,
           "target_share": TARGET_SHARE, "against": args.against, "trials": {}}
    print(f"sphere-mouse --replay SESSION --speed {args.speed:g} (default config), the page's frame messages: the "
          f"drawn centre within {TARGET_PX:g} px of the true one, and where the error comes from")
    worst = {tree: 1.0 for tree, _ in sides}
    try:
        for name, start in stretches:
            try:
                rt = trials.rendered_trial(name, start, args.seconds, occlusions=trials.eval_occlusions(),
                                           jpeg_quality=85)
            except ValueError as e:
                print(f"sphere bench ar: {e}", file=sys.stderr)
                return 2
            session = folder / f"{rt.name}-{start:g}"
            if session.exists():
                shutil.rmtree(session)
            bases = trials.write_session(rt, session, lead_s=args.lead)
            figs = {}
            for tree, host_dir in (sides if len(doc["trials"]) % 2 == 0 else sides[::-1]):  # who goes first alternates
                figs[tree] = judge(replay(session, args.speed, folder, types=("frame",), host_dir=host_dir), rt,
                                   bases["lead_s"])
            doc["trials"][f"{rt.name}:{start:g}"] = figs[THIS]
            if args.against:
                doc.setdefault("against_trials", {})[f"{rt.name}:{start:g}"] = figs[args.against]
            for tree, _ in sides:
                fig = figs[tree]
                side = f" ({tree})" if args.against else ""
                print(f"\n{rt.name}:{start:g}{side}: {fig['frames']} of {fig['of']} frames drawn")
                if not fig["frames"]:
                    worst[tree] = 0.0
                    continue
                worst[tree] = min(worst[tree], fig["within"])
                print(f"  within {TARGET_PX:g} px: {100 * fig['within']:.1f} % of the frames; ball seen "
                      f"{100 * fig['within_seen']:.1f} %, in the 1 s loss {100 * (fig['within_loss'] or 0):.1f} % of "
                      f"{fig['loss_frames']} (worst {fig['worst_loss_px'] or 0:.1f} px)")
                print(f"  {'stage':10}{'within':>9}{'median px':>11}{'p95 px':>9}")
                for stage, s in fig["stages"].items():
                    print(f"  {stage:10}{100 * s['within']:>8.1f}%{_num(s['median_px']):>11}{_num(s['p95_px']):>9}")
    finally:
        tmp.cleanup()
    for tree, _ in sides:
        state = "met" if worst[tree] >= TARGET_SHARE else "MISSED"
        side = f" ({tree})" if args.against else ""
        print(f"\ntarget{side}: ≥ {100 * TARGET_SHARE:.0f} % of the frames within {TARGET_PX:g} px on every stretch: "
              f"{state} (worst {100 * worst[tree]:.1f} %)")
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=2, default=float))
        print(f"wrote {args.json}", file=sys.stderr)
    return 0


def _num(v) -> str:
    return "–" if v is None else f"{v:.2f}"
