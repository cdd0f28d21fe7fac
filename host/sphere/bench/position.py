"""The 3-D stream's position smoothing (:mod:`sphere.smoothing.position`), cross-validated on rendered trials.

Motion: BROAD trials seen by the virtual webcam exactly as `sphere hybrid-eval` renders them (the same
camera, clutter, JPEG coding, capture latency, a hand over a third of the ball at 3-4 s and over all of it
at 7-8 s). The hybrid tracker runs on them as on a live system (:func:`sphere.camera.evaluation.run`); its
output at the IMU's rate then goes through the daemon's own :class:`~sphere.smoothing.pose.PoseFilter`
with each position filter setting, as ``SphereMouse`` calls it (an unknown position resets the filter).

Tuning (the pointer bench's rule): settings are chosen on the TRAIN stretches (other stretches of the
same trials and a fast rotation trial, another render seed) and every figure printed is measured on the
TEST stretches, `sphere hybrid-eval`'s own. Rule: the least worst ratio of a figure to its target (mean over
the stretches): RMSE lateral ≤ 5 mm and depth ≤ 10 mm (issue 30's slow-motion goal), jitter at rest
lateral ≤ 1 mm and depth ≤ 3 mm, lag ≤ 10 ms (issue 16's); a figure missing on every stretch (no rest
phase) does not count.
"""

from __future__ import annotations

import json
import math
import sys

import numpy as np

from sphere import argtypes, broad
from sphere.camera import evaluation as ev
from sphere.camera import trials
from sphere.commands.hybrid_eval import refused
from sphere.smoothing.pose import PoseFilter
from sphere.smoothing.registry import POSITION, POSITION_DEFAULT

HELP = "position smoothing of the 3-D stream: RMSE, jitter, lag per filter, cross-validated on rendered trials"

TRAIN = "10:100,14:120,16:100,07:40"
TEST = "10:40,14:64,16:40"  # sphere hybrid-eval's default trials
TRAIN_SEED = 2
TEST_SEED = 1  # hybrid-eval's
TARGETS = {"rmse_lateral_m": 0.005, "rmse_depth_m": 0.010, "jitter_lateral_m": 0.001, "jitter_depth_m": 0.003,
           "latency_ms": 10.0}
FAST_TARGETS = {**TARGETS, "rmse_lateral_m": 0.008, "rmse_depth_m": 0.012}
OWN_RATIO = 1.3  # the smoothed position's RMSE against the hybrid's own, on every stretch (issue 30)


def targets(trial_name: str) -> dict:
    return FAST_TARGETS if "fast" in trial_name else TARGETS


def add_arguments(p) -> None:
    p.add_argument("--train", type=argtypes.stretches, default=TRAIN, help=f"trial:start_s stretches to choose on (default {TRAIN})")
    p.add_argument("--test", type=argtypes.stretches, default=TEST, help=f"trial:start_s stretches to score on (default {TEST}, hybrid-eval's)")
    p.add_argument("--seconds", type=argtypes.seconds, default=12.0, help="length of each stretch (default 12, at least 9)")
    p.add_argument("--json", metavar="OUT", type=argtypes.out_file, help="write the figures as JSON")


def render_runs(stretches, seconds: float, seed: int):
    """[(name, Run, RenderedTrial)] of the hybrid tracker on each rendered stretch (hybrid-eval's scene)."""
    occl = trials.eval_occlusions()
    out = []
    for name, start in stretches:
        rt = trials.rendered_trial(name, start, seconds, occlusions=occl, seed=seed, jpeg_quality=85)
        out.append((f"{name}:{start:g}", ev.run(rt), rt))
    return out


def smoothed(run, name: str, params: dict):
    """The hybrid's output through the daemon's PoseFilter with position filter ``name``."""
    f = PoseFilter("none", (name, params))
    est = run.est["hybrid"]
    out = np.full_like(est, np.nan)
    q = (1.0, 0.0, 0.0, 0.0)
    for i, t in enumerate(run.t_out):
        p = est[i]
        if np.all(np.isfinite(p)):
            out[i] = f.at(q, int(round(t * 1e6)), p)[1]
        else:
            f.at(q, int(round(t * 1e6)))
    return out


def score(figs: list) -> tuple[float, dict]:
    """(worst ratio to the targets, mean figures) over [(figures, targets, the unfiltered figures)] of the
    stretches."""
    mean, ratios = {}, []
    for k in TARGETS:
        have = [(f[k], t[k]) for f, t, _ in figs if f.get(k) is not None]
        mean[k] = float(np.mean([v for v, _ in have])) if have else None
        if have:
            ratios.append(float(np.mean([max(v, 0.0) / lim for v, lim in have])))
    for k in ("rmse_lateral_m", "rmse_depth_m"):  # never more than 1.3× the hybrid's own error, on any stretch
        own = [f[k] / raw[k] / OWN_RATIO for f, _, raw in figs if f.get(k) and raw.get(k)]
        if own:
            ratios.append(max(own))
    return max(ratios), mean


def evaluate(runs, name: str, params: dict):
    return score([(ev.method_figures(r, rt, smoothed(r, name, params)), targets(rt.name),
                   ev.method_figures(r, rt, r.est["hybrid"])) for _, r, rt in runs])


def run(args) -> int:
    code = refused("sphere bench position", args.seconds,
                   [n for n, _ in args.train + args.test])
    if code is not None:
        return code

    try:
        train = render_runs(args.train, args.seconds, TRAIN_SEED)
        test = render_runs(args.test, args.seconds, TEST_SEED)
    except (broad.BroadMissing, ValueError) as e:
        print(f"sphere bench position: {e}", file=sys.stderr)
        return 2
    print(f"train: {', '.join(n for n, _, _ in train)} (render seed {TRAIN_SEED}); "
          f"test: {', '.join(n for n, _, _ in test)} (seed {TEST_SEED}, hybrid-eval's)")
    head = f"{'':34}{'worst':>7}{'lat mm':>8}{'dep mm':>8}{'jit lat':>8}{'jit dep':>8}{'lag ms':>8}"
    print(head)
    doc = {"train": [n for n, _, _ in train], "test": [n for n, _, _ in test], "targets": TARGETS, "filters": {}}
    best = None
    for name in POSITION:
        defaults = {k: p.default for k, p in POSITION.params(name).items()}
        settings = POSITION.grid(name)
        tried = [(evaluate(train, name, s)[0], s) for s in settings]
        w, pick = min(tried, key=lambda x: x[0])
        rows = {}
        for label, s in (("defaults", defaults), ("cross-validated pick", pick)):
            worst, fig = evaluate(test, name, s)
            rows[label] = {"params": s, "worst_ratio": worst, "figures": fig}
            print(f"{(name + ' ' + label):34}{worst:>7.2f}" + "".join(_cell(fig[k], k) for k in TARGETS)
                  + (f"  {_params(s)}" if s else ""))
        doc["filters"][name] = {"train_worst_ratio": w, **rows}
        if best is None or w < best[0]:
            best = (w, name, pick)
    w, name, pick = best
    doc["choice"] = {"filter": name, "params": pick, "train_worst_ratio": w}
    print(f"\nchosen on the train stretches (least worst ratio {w:.2f}): {name} {_params(pick)}".rstrip()
          + f"; the default is {POSITION_DEFAULT}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(doc, f, indent=2)
        print(f"wrote {args.json}", file=sys.stderr)
    return 0


def _cell(v, k):
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return f"{'–':>8}"
    return f"{v:>8.1f}" if k == "latency_ms" else f"{1000 * v:>8.2f}"


def _params(s: dict) -> str:
    return " ".join(f"{k}={v:g}" for k, v in s.items())
