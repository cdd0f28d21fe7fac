"""Where SphereFilter's error comes from on BROAD, per trial and per second, beside VQF's.

    python -m sphere.fusion.diagnose [--only 07,09] [--seconds N] [--json OUT]
    python -m sphere.fusion.diagnose --stress fast_rest,fast_combined [--seeds 100-109]

For every shipped trial (``sphere.paths.broad_dir``) both filters run as `sphere eval` runs them (the registry's
defaults; VQF with its published ones) with their diagnostics, scored with the dataset's metric. ``--stress KINDS``
does the same on stress traces (:mod:`sphere.fusion.stress`, known truth) of those kinds, seeds 100–109 by default:
the seeds looked at while designing, never the report's 1000 on (`sphere bench stress`). Printed per trial:

- the RMSE split into heading and inclination, for both filters;
- the same by how fast the sensor turns (its gyro rate averaged over 0.5 s: still below 5 °/s, slow to 200 °/s,
  fast above): each class's share of the scored time and what it adds to the heading's and inclination's mean
  square (so the three add up to the whole), for both filters;
- the heading error by the state of SphereFilter's disturbance test: the share of scored time the field was
  rejected (heading on the gyro) and the RMS heading error there and while the field was accepted;
- the bias estimate against the bias a rest shows: at every rest of 3 s or more after the first, the mean gyro over
  the rest (the bias then, within the gyro's noise) minus each filter's estimate 2 s before SphereFilter flagged the
  rest (what the motion before it left), as the norm and its earth-vertical part (the part that turns into heading), °/s;
- the seconds where SphereFilter is furthest behind VQF (per-second RMS of the total error), with the state then;
- each part switched off in turn (``sphere_filter.PARTS``): the trial's total RMSE without it, minus with it
  (negative: the part costs accuracy on this trial).

It runs each trial about seven times (the parts); SphereFilter is pure Python, so budget a few minutes of one core.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from sphere import broad
from sphere.chips import STANDARD_GRAVITY_M_S2
from sphere.fusion import factory, peers, stress
from sphere.fusion.sphere_filter import PARTS

DEG = np.pi / 180.0
REST_MIN_S = 3.0


def _rms(x) -> float:
    x = np.asarray(x, float)
    return float(np.sqrt(np.mean(x * x))) if len(x) else float("nan")


def _run(name: str, trial, **params):
    f = factory.make_for_trial(name, trial.gyr_rad_s, trial.acc_m_s2, trial.mag_uT, trial.dt_s, **params)
    d = f.update_batch(trial.gyr_rad_s, trial.acc_m_s2, trial.mag_uT, trial.dt_s, diagnostics=True)
    d["quat"] = peers.to_enu(d["quat"], f.earth_frame)
    return d


def _errors(q_enu, trial):
    """Per-sample total, heading, inclination (°), NaN where the reference is missing."""
    out = np.full((3, len(trial)), np.nan)
    ok = np.all(np.isfinite(trial.opt_quat), axis=1)
    out[:, ok] = broad.error_angles_deg(q_enu[ok], trial.opt_quat[ok])
    return out


def _rests(flag, gyr, rate_hz):
    """(start, end) sample spans of the rests of REST_MIN_S or more after the first 5 s (the opening rest left out)."""
    flag = np.asarray(flag, bool)
    edges = np.flatnonzero(np.diff(np.r_[0, flag.astype(np.int8), 0]))
    spans = [(a, b) for a, b in zip(edges[::2], edges[1::2]) if b - a >= REST_MIN_S * rate_hz]
    return [s for s in spans if s[0] > 5.0 * rate_hz]


def _bias_at_rests(spans, d, trial):
    """For each rest: the rest's mean gyro minus the estimate when the rest began; norm and earth-vertical part."""
    rows = []
    for a, b in spans:
        truth = trial.gyr_rad_s[a:b].mean(axis=0)
        # 2 s before the flag: the sensor had been still for rest_min_s (1.5 s, both filters) when it rose, so this
        # is the estimate the motion left, before either filter's rest measurement could act
        e = truth - d["bias_rad_s"][max(a - int(2.0 * trial.rate_hz), 0)]
        q = d["quat"][a]
        # earth-vertical component of the sensor-frame error: the third row of R(q) · e
        w, x, y, z = q
        up = np.array([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])
        rows.append((float(np.linalg.norm(e) / DEG), float(up @ e / DEG)))
    return rows


#: the turning-rate classes (°/s, gyro rate averaged over RATE_WINDOW_S): still, slow, fast
RATE_CLASSES = (("still", 0.0, 5.0), ("slow", 5.0, 200.0), ("fast", 200.0, np.inf))
RATE_WINDOW_S = 0.5


def _by_rate(trial, use, errors: dict) -> dict:
    """Per rate class: its share of the scored samples and each filter's heading / inclination mean square over
    the class's samples divided by all scored samples (the classes add up to the whole mean square)."""
    w = np.degrees(np.linalg.norm(trial.gyr_rad_s, axis=1))
    n = max(1, int(RATE_WINDOW_S * trial.rate_hz))
    w = np.convolve(w, np.ones(n) / n, mode="same")
    total = max(int(use.sum()), 1)
    out = {}
    for name, lo, hi in RATE_CLASSES:
        m = use & (w >= lo) & (w < hi)
        row = {"share": float(m.sum() / total)}
        for f, e in errors.items():
            row[f"{f}_heading_ms"] = float(np.sum(e[1][m] ** 2) / total)
            row[f"{f}_incl_ms"] = float(np.sum(e[2][m] ** 2) / total)
        out[name] = row
    return out


def stress_trial(kind: str, seed: int):
    """A stress trace as a trial (its truth as the reference, its scored samples as the movement)."""
    tr = stress.trace(kind, seed)
    return broad.Trial(f"{kind} seed {seed}", 1.0 / tr.dt_s, tr.gyr_rad_s, tr.acc_m_s2, tr.mag_uT, tr.quat,
                       tr.scored)


def diagnose_trial(trial, parts: bool = True) -> dict:
    sp = _run("sphere", trial)
    res = {"trial": trial.name}
    try:
        vq = _run("vqf", trial)
    except peers.PeerMissing:
        vq = None
    use = trial.movement & np.all(np.isfinite(trial.opt_quat), axis=1)
    es = _errors(sp["quat"], trial)
    res["sphere"] = {m: _rms(es[i][use]) for i, m in enumerate(broad.OrientationError.__dataclass_fields__)}
    if vq is not None:
        ev = _errors(vq["quat"], trial)
        res["vqf"] = {m: _rms(ev[i][use]) for i, m in enumerate(broad.OrientationError.__dataclass_fields__)}
    res["by_rate"] = _by_rate(trial, use, {"sphere": es, **({"vqf": ev} if vq is not None else {})})
    dist = np.asarray(sp["mag_disturbed"], bool)
    res["rejected_share"] = float(dist[use].mean())
    res["heading_rms_rejected"] = _rms(es[1][use & dist])
    res["heading_rms_accepted"] = _rms(es[1][use & ~dist])
    spans = _rests(sp["rest"], trial.gyr_rad_s, trial.rate_hz)
    res["bias_at_rests"] = {"sphere": _bias_at_rests(spans, sp, trial)}
    if vq is not None:
        res["bias_at_rests"]["vqf"] = _bias_at_rests(spans, vq, trial)
    res["rest_starts_s"] = [a / trial.rate_hz for a, _ in spans]
    # per second: RMS of the scored samples' errors, with the state then
    n_s = int(len(trial) / trial.rate_hz)
    sec = []
    for k in range(n_s):
        a, b = int(k * trial.rate_hz), int((k + 1) * trial.rate_hz)
        u = use[a:b]
        if u.sum() < 0.5 * (b - a):
            continue
        row = {"s": k, "sphere_total": _rms(es[0][a:b][u]), "sphere_heading": _rms(es[1][a:b][u]),
               "sphere_incl": _rms(es[2][a:b][u]), "rejected": float(dist[a:b].mean()),
               "gyr_dps": float(np.degrees(np.linalg.norm(trial.gyr_rad_s[a:b], axis=1).mean())),
               "acc_dev_m_s2": float(np.abs(np.linalg.norm(trial.acc_m_s2[a:b], axis=1) - STANDARD_GRAVITY_M_S2).mean())}
        if vq is not None:
            row.update(vqf_total=_rms(ev[0][a:b][u]), vqf_heading=_rms(ev[1][a:b][u]), vqf_incl=_rms(ev[2][a:b][u]))
        sec.append(row)
    res["seconds"] = sec
    if parts:
        base = res["sphere"]["total"]
        res["without"] = {}
        for part in PARTS:
            d = _run("sphere", trial, **{part: False})
            res["without"][part] = float(broad.orientation_error(d["quat"], trial).total - base)
    return res


def format_trial(r: dict, worst: int = 3) -> str:
    s, v = r["sphere"], r.get("vqf")
    out = [f"{r['trial']}"]
    vs = (f"   vqf {v['total']:.2f} (heading {v['heading']:.2f}, incl. {v['inclination']:.2f})"
          f"   ratio {s['total'] / v['total']:.2f}") if v else ""
    out.append(f"  sphere {s['total']:.2f} (heading {s['heading']:.2f}, incl. {s['inclination']:.2f}){vs}")
    rows = []
    for cls, x in r["by_rate"].items():
        row = f"{cls} {100 * x['share']:.0f} %: sphere {x['sphere_heading_ms']:.2f} / {x['sphere_incl_ms']:.2f}"
        if v:
            row += f", vqf {x['vqf_heading_ms']:.2f} / {x['vqf_incl_ms']:.2f}"
        rows.append(row)
    out.append("  by turning rate, share and mean square (°²) heading / inclination: " + "; ".join(rows))
    out.append(f"  field rejected {100 * r['rejected_share']:.0f} % of scored time; heading RMS there "
               f"{r['heading_rms_rejected']:.2f}, accepted {r['heading_rms_accepted']:.2f}")
    for name, rows in r["bias_at_rests"].items():
        if rows:
            out.append(f"  bias error at rest starts ({name}, °/s, norm/vertical): "
                       + ", ".join(f"{t:.0f}s {n:.2f}/{u:+.2f}" for t, (n, u) in zip(r["rest_starts_s"], rows)))
    if v:
        secs = sorted(r["seconds"], key=lambda x: x["vqf_total"] - x["sphere_total"])[:worst]
        for x in secs:
            out.append(f"  behind VQF at {x['s']:4d} s: sphere {x['sphere_total']:.2f} (h {x['sphere_heading']:.2f}, "
                       f"i {x['sphere_incl']:.2f}) vqf {x['vqf_total']:.2f} (h {x['vqf_heading']:.2f}, "
                       f"i {x['vqf_incl']:.2f}); |ω| {x['gyr_dps']:.0f} °/s, ||a|−g| {x['acc_dev_m_s2']:.1f}, "
                       f"rejected {100 * x['rejected']:.0f} %")
    if "without" in r:
        out.append("  without each part (Δ total, °): " + ", ".join(f"{k} {d:+.2f}" for k, d in r["without"].items()))
    return "\n".join(out)


def format_means(results: list) -> str:
    """The mean over the stress seeds of each kind: total, heading, inclination RMSE and the rate classes."""
    out = []
    for kind in dict.fromkeys(r["trial"].split(" seed ")[0] for r in results):
        rs = [r for r in results if r["trial"].split(" seed ")[0] == kind]
        line = f"{kind}, mean of {len(rs)} seeds:"
        for f in ("sphere", "vqf"):
            if all(f in r for r in rs):
                m = {k: float(np.mean([r[f][k] for r in rs])) for k in ("total", "heading", "inclination")}
                line += f"  {f} {m['total']:.2f} ({m['heading']:.2f} / {m['inclination']:.2f})"
        out.append(line)
        for cls in rs[0]["by_rate"]:
            x = {k: float(np.mean([r["by_rate"][cls][k] for r in rs])) for k in rs[0]["by_rate"][cls]}
            row = f"    {cls} {100 * x['share']:.0f} %: mean square heading / incl. sphere {x['sphere_heading_ms']:.2f} / " \
                  f"{x['sphere_incl_ms']:.2f}"
            if "vqf_heading_ms" in x:
                row += f", vqf {x['vqf_heading_ms']:.2f} / {x['vqf_incl_ms']:.2f}"
            out.append(row)
    return "\n".join(out)


def _kinds(text: str) -> list:
    names = [k.strip() for k in text.split(",") if k.strip()]
    bad = [k for k in names if k not in stress.KINDS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"{','.join(bad) or text!r}: not a stress kind; the stress kinds are "
                                         + ", ".join(stress.KINDS))
    return names


def _seed_range(text: str) -> range:
    try:
        a, _, b = text.partition("-")
        r = range(int(a), int(b or a) + 1)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a seed range like 100-109") from None
    if not len(r) or r.start < 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a seed range like 100-109 (first ≤ last, not negative)")
    return r


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--only", help="comma-separated trial numbers or names (default: every shipped trial)")
    p.add_argument("--seconds", type=float, help="only the first S seconds of each trial")
    p.add_argument("--no-parts", action="store_true", help="skip the runs with each part switched off")
    p.add_argument("--json", help="write everything (per-second rows too) here")
    p.add_argument("--stress", type=_kinds,
                   help="comma-separated stress kinds instead of the BROAD trials")
    p.add_argument("--seeds", type=_seed_range, default=range(100, 110),
                   help="stress seeds FIRST-LAST (default 100-109; 1000 on are the report's)")
    args = p.parse_args(argv)
    if args.stress and args.only:
        p.error("--only picks BROAD trials; with --stress give --seeds")
    if args.stress:
        trials = [(stress_trial, (k, s)) for k in args.stress for s in args.seeds]
    else:
        try:
            paths = ([broad.find_trial(n) for n in args.only.split(",")] if args.only else broad.trial_paths())
        except broad.BroadMissing as e:
            print(f"sphere.fusion.diagnose: {e}", file=sys.stderr)
            return 1
        trials = [(broad.load_trial, (path,)) for path in paths]
    results = []
    for load, load_args in trials:
        trial = load(*load_args)
        if args.seconds:
            trial = trial.seconds(0.0, args.seconds)
        r = diagnose_trial(trial, parts=not args.no_parts)
        results.append(r)
        print(format_trial(r), flush=True)
    if args.stress:
        print(format_means(results), flush=True)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
