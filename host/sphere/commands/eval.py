"""`sphere eval`: orientation filters on BROAD trials with the dataset's own error metric."""

from __future__ import annotations

import argparse
import hashlib
import inspect
import json
import math
import multiprocessing
import sys
import time
from pathlib import Path

import numpy as np

from sphere import argtypes, broad, quaternion
from sphere import quaternion as quat
from sphere.fusion import common, crossval, factory, peers, registry
from sphere.paths import broad_dir
from sphere.progress import bar

HELP = "evaluate orientation filters on BROAD trials (total/heading/inclination RMSE, µs per sample)"
DESCRIPTION = """\
Runs orientation filters on every BROAD trial (.mat) in a folder and prints, per trial and as the mean
over trials, the RMSE of the total, heading and inclination error in degrees, as the dataset's authors
define them (Laidig et al., Data 6(7):72, 2021, CC BY 4.0): q_err = q_est ⊗ q_ref⁻¹ in the earth frame,
over movement phases with a valid optical reference. Every filter's output is converted to ENU first
(NWU → ENU: q = [√½, 0, 0, √½] ⊗ q). Also prints microseconds per sample for each filter in this run.
Filters: madgwick, dissertation-kf, sphere (ours) and the peers vqf, fusion, ahrs-madgwick, ahrs-mahony,
ahrs-ekf (optional packages; a missing one is skipped with a message). With --cv, every free parameter
of our filters is chosen from its registry grid on the other trials and scored on the one left out
(leave-one-trial-out): the figures that do not flatter."""

METRICS = ("total", "heading", "inclination")
#: The groups of BROAD's trials.json used in the summary (the ones the targets talk about).
GROUPS = ("rotation", "translation", "disturbed", "undisturbed")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--trials", metavar="DIR", help="folder of BROAD .mat trials (default: ../shared/data/broad, "
                   "or SPHERE_BROAD_DIR)")
    p.add_argument("--filters", metavar="NAMES", help="comma-separated filter names (default: all)")
    p.add_argument("--only", metavar="TRIALS", help="comma-separated trial numbers or names to run (default: all)")
    p.add_argument("--seconds", type=argtypes.seconds, metavar="S", help="use only the first S seconds of each trial (quick check)")
    p.add_argument("--json", metavar="OUT", type=argtypes.out_file, help="write the results as JSON")
    p.add_argument("--plot", metavar="DIR", type=argtypes.plot_dir,
                   help="write PNG plots (error over time per trial, bar chart per filter)")
    p.add_argument("--jobs", type=argtypes.at_least_one, default=2, help="trials run in parallel (default: 2)")
    p.add_argument("--quiet", action="store_true", help="print only the mean table")
    p.add_argument("--cv", action="store_true", help="leave-one-trial-out: each filter's free parameters chosen "
                   "from its registry grid on the other trials, scored on the one left out (default filters: "
                   "ours and vqf)")
    p.add_argument("--cache", metavar="DIR", help="with --cv: keep each (trial, filter, parameters) result in DIR "
                   "and reuse it while the fusion code is unchanged")


def run_filter(name: str, trial, keep_errors: bool = False, diagnostics: bool = False, **params) -> dict:
    """One filter on one trial: RMSEs, µs per sample, settings, and the signed heading offset.

    ``params`` replace the registry's defaults (``--cv`` grid points). ``diagnostics`` keeps the filter's
    per-sample diagnostics (rest, bias, magnetic disturbance) where it has them."""
    f = factory.make_for_trial(name, trial.gyr_rad_s, trial.acc_m_s2, trial.mag_uT, trial.dt_s, **params)
    diag = None
    t0 = time.perf_counter()
    if diagnostics and getattr(f, "diagnostics", None):
        diag = f.update_batch(trial.gyr_rad_s, trial.acc_m_s2, trial.mag_uT, trial.dt_s, diagnostics=True)
        q = diag.pop("quat")
    else:
        q = f.update_batch(trial.gyr_rad_s, trial.acc_m_s2, trial.mag_uT, trial.dt_s)
    elapsed = time.perf_counter() - t0
    q_enu = peers.to_enu(q, f.earth_frame)
    err = broad.orientation_error(q_enu, trial)
    out = {"errors": err.as_dict(), "us_per_sample": 1e6 * elapsed / len(trial),
           "settings": registry.settings(name, f), "heading_offset_deg": heading_offset_deg(q_enu, trial)}
    if keep_errors:
        use = np.all(np.isfinite(trial.opt_quat), axis=1)
        tot = np.full(len(trial), np.nan)
        tot[use] = broad.error_angles_deg(q_enu[use], trial.opt_quat[use])[0]
        out["total_over_time"] = tot
        out["movement"] = trial.movement
    if diag is not None:
        out["diagnostics"] = diag
    return out


def heading_offset_deg(q_enu: np.ndarray, trial) -> float:
    """Circular mean of the signed heading error over the samples that count (a constant offset shows here)."""
    use = trial.movement & np.all(np.isfinite(trial.opt_quat), axis=1)
    e = quat.multiply(quat.normalize(q_enu[use]), quat.conjugate(quat.normalize(trial.opt_quat[use])))
    e = e * np.sign(e[:, :1] + 1e-300)
    ang = 2.0 * np.arctan2(e[:, 3], e[:, 0])
    return float(np.degrees(np.arctan2(np.mean(np.sin(ang)), np.mean(np.cos(ang)))))


def _scored(trial) -> bool:
    """Whether the dataset's metric scores anything of ``trial``: a movement sample with a finite reference."""
    return bool((trial.movement & np.all(np.isfinite(trial.opt_quat), axis=1)).any())


def _trial_job(args):
    path, names, seconds, keep = args

    trial = broad.load_trial(path)
    if seconds:
        trial = trial.seconds(0.0, seconds)
    if not _scored(trial):
        return trial.name, None, (trial.rate_hz, len(trial))  # nothing the metric scores: run() leaves it out
    res = {}
    for name in names:
        try:
            res[name] = run_filter(name, trial, keep, diagnostics=keep)
        except peers.PeerMissing as e:
            res[name] = {"missing": str(e)}
    return trial.name, res, (trial.rate_hz, len(trial))


def _trial_progress(total: int):
    """A tqdm bar over the trials on a terminal (sphere.progress); elsewhere one line per finished trial."""
    trials = bar(total=total, desc="eval", unit="trial")

    def done(name: str) -> None:
        trials.set_postfix_str(name, refresh=False)
        trials.update(1)
        if trials.disable:
            print(f"  done {name}", file=sys.stderr)
        if trials.n >= total:
            trials.close()

    return done


def evaluate(paths, names, seconds=None, jobs=1, keep_errors=False, progress=None):
    """Run ``names`` on every trial; returns {trial: {filter: result}} in trial order (None for a trial with no
    movement sample that has a reference: none in its first ``seconds``)."""
    jobs_list = [(p, list(names), seconds, keep_errors) for p in paths]
    results = {}
    if jobs > 1 and len(paths) > 1:
        with multiprocessing.get_context("spawn").Pool(min(jobs, len(paths))) as pool:
            for tname, res, _ in pool.imap(_trial_job, jobs_list):
                results[tname] = res
                if progress:
                    progress(tname)
    else:
        for j in jobs_list:
            tname, res, _ = _trial_job(j)
            results[tname] = res
            if progress:
                progress(tname)
    return results


def summarise(results: dict, names, groups_of=None) -> dict:
    """The JSON document of issue 5: {"filters": {NAME: {"trials", "mean", "us_per_sample", "settings"}}, ...}."""
    doc = {"filters": {}, "groups": {}, "heading_offset_deg": {}, "metric": METRIC_NOTE,
           "dataset": "BROAD (Laidig, Caruso, Cereatti, Seel; Data 6(7):72, 2021; CC BY 4.0)"}
    trials = list(results)
    for name in names:
        rows = {t: results[t][name] for t in trials if "errors" in results[t].get(name, {})}
        if not rows:
            missing = next((results[t][name]["missing"] for t in trials if "missing" in results[t].get(name, {})), None)
            if missing:
                doc.setdefault("missing", {})[name] = missing
            continue
        n_total = sum(1 for _ in rows)
        doc["filters"][name] = {
            "trials": {t: r["errors"] for t, r in rows.items()},
            "mean": {m: float(np.mean([r["errors"][m] for r in rows.values()])) for m in METRICS},
            "us_per_sample": float(np.mean([r["us_per_sample"] for r in rows.values()])),
            "settings": next(iter(rows.values()))["settings"],
        }
        doc["heading_offset_deg"][name] = {t: r["heading_offset_deg"] for t, r in rows.items()}
        if groups_of:
            g = {}
            for group in GROUPS:
                member = [t for t in rows if group in groups_of.get(t, ())]
                if member:
                    g[group] = {m: float(np.mean([rows[t]["errors"][m] for t in member])) for m in METRICS}
                    g[group]["trials"] = len(member)
            doc["groups"][name] = g
        assert n_total == len(rows)
    return doc


METRIC_NOTE = (
    "RMSE over movement samples with a finite optical reference; q_err = q_est ⊗ q_opt⁻¹ (earth frame); total = "
    "2·acos|w|, heading = 2·atan|z/w|, inclination = 2·acos√(w²+z²); mean over trials. As in BROAD's own "
    "evaluation code (example_code/broad_utils.py, process_data.py), no heading offset between magnetic north and "
    "the optical frame is removed: the dataset's optical frame is already aligned with magnetic north; the "
    "heading_offset_deg table (circular mean of the signed heading error per trial) shows what remains."
)


def trial_groups(directory) -> dict:
    """{trial stem: [groups]} from the folder's trials.json (BROAD's grouping), or {} without one."""
    p = Path(directory) / "trials.json"
    if not p.exists():
        return {}
    info = json.loads(p.read_text())
    return {name: list(v.get("groups", [])) for name, v in info.get("trials", {}).items()}


def _fmt_table(title, rows, cols, fmt="{:8.2f}"):
    lines = [title]
    w = max(16, max((len(r) for r in rows), default=0) + 1)
    lines.append(" " * w + "".join(f"{c:>14}" for c in cols))
    for name, vals in rows.items():
        cells = []
        for c in cols:
            v = vals.get(c)
            cells.append(f"{'—':>14}" if v is None else f"{fmt.format(v):>14}")
        lines.append(f"{name:<{w}}" + "".join(cells))
    return "\n".join(lines)


def format_report(doc: dict, quiet: bool = False) -> str:
    out = []
    filters = doc["filters"]
    trials = sorted({t for f in filters.values() for t in f["trials"]})
    if not quiet:
        for t in trials:
            rows = {n: f["trials"][t] for n, f in filters.items() if t in f["trials"]}
            out.append(_fmt_table(f"trial {t}: RMSE (°)", rows, METRICS))
            out.append("")
    rows = {n: dict(f["mean"], us_per_sample=f["us_per_sample"]) for n, f in filters.items()}
    out.append(_fmt_table(f"mean over {len(trials)} trials: RMSE (°), and µs per sample", rows,
                          METRICS + ("us_per_sample",)))
    if doc.get("groups"):
        out.append("")
        rows = {n: {g: v["total"] for g, v in gs.items()} for n, gs in doc["groups"].items()}
        out.append(_fmt_table("mean total RMSE (°) by BROAD group", rows, GROUPS))
    if doc.get("heading_offset_deg") and not quiet:
        out.append("")
        short = {t: t.split("_", 1)[0] for t in trials}
        rows = {n: {short[t]: v for t, v in hs.items()} for n, hs in doc["heading_offset_deg"].items()}
        out.append(_fmt_table("signed mean heading error per trial (°): a shared constant here would be a "
                              "north offset of the reference", rows, tuple(short[t] for t in trials), "{:6.1f}"))
    out.append("")
    out.append("settings:")
    for n, f in filters.items():
        s = ", ".join(f"{k}={v}" for k, v in f["settings"].items())
        out.append(f"  {n}: {s}")
    for n, msg in doc.get("missing", {}).items():
        out.append(f"  {n}: skipped: {msg}")
    out.append("")
    out.append("metric: " + doc["metric"])
    out.append("data: " + doc["dataset"])
    return "\n".join(out)


def write_plots(directory: Path, doc: dict, results: dict) -> list[Path]:
    try:
        import matplotlib  # optional: matplotlib (the plot extra)

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # optional: matplotlib (the plot extra)
    except ImportError:
        raise SystemExit("sphere eval --plot needs matplotlib: pip install 'marg-sphere[plot]'")
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for tname, res in results.items():
        p = directory / f"error_{tname}.png"
        _plot_trial(plt, p, tname, res)
        written.append(p)
    names = list(doc["filters"])
    fig, ax = plt.subplots(figsize=(max(6, 1.2 * len(names)), 4))
    x = np.arange(len(names))
    for i, m in enumerate(METRICS):
        ax.bar(x + (i - 1) * 0.27, [doc["filters"][n]["mean"][m] for n in names], 0.27, label=m)
    ax.set_xticks(x, names, rotation=20)
    ax.set_ylabel("mean RMSE over trials (°)")
    ax.set_title("BROAD: mean RMSE per filter")
    ax.legend()
    fig.tight_layout()
    p = directory / "mean_rmse_by_filter.png"
    fig.savefig(p, dpi=100)
    plt.close(fig)
    written.append(p)
    return written


RATE_HZ = 285.714285714


def _plot_trial(plt, path: Path, tname: str, res: dict) -> None:
    """The total error over time and, under it on the same time axis, each diagnosing filter's gyro bias
    estimate with its rest (green) and magnetic-disturbance (red) phases shaded."""
    diag = {n: r["diagnostics"] for n, r in res.items() if "diagnostics" in r}
    fig, axes = plt.subplots(1 + len(diag), 1, figsize=(11, 3.2 + 2.0 * len(diag)), sharex=True,
                             gridspec_kw={"height_ratios": [2.0] + [1.0] * len(diag)}, squeeze=False)
    ax = axes[0][0]
    movement = None
    for name, r in res.items():
        if "total_over_time" in r:
            y = r["total_over_time"]
            ax.plot(np.arange(len(y)) / RATE_HZ, y, lw=0.7, label=name)
            movement = r.get("movement", movement)
    if movement is not None:
        _shade(ax, ~np.asarray(movement, bool), "0.85", "not scored (no movement)")
    ax.set_ylabel("total error (°)")
    ax.set_title(f"{tname}: total orientation error (BROAD, CC BY 4.0)")
    ax.legend(fontsize=7, ncol=5, loc="upper left")
    ax.set_ylim(bottom=0)
    for (name, d), row in zip(diag.items(), axes[1:]):
        ax = row[0]
        b = np.degrees(np.asarray(d["bias_rad_s"]))
        t = np.arange(len(b)) / RATE_HZ
        for k, axis in enumerate("xyz"):
            ax.plot(t, b[:, k], lw=0.8, label=f"bias {axis}")
        _shade(ax, d["rest"], "tab:green", "rest")
        _shade(ax, d["mag_disturbed"], "tab:red", "mag. disturbed")
        ax.set_ylabel(f"{name}\nbias (°/s)")
        ax.legend(fontsize=7, ncol=5, loc="upper left")
    axes[-1][0].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _shade(ax, flag, color, label):
    """Shade the spans where ``flag`` is set (one legend entry)."""
    flag = np.asarray(flag, bool)
    if not flag.any():
        return
    edges = np.flatnonzero(np.diff(np.r_[0, flag.astype(np.int8), 0]))
    for i, (a, b) in enumerate(zip(edges[::2], edges[1::2])):
        ax.axvspan(a / RATE_HZ, b / RATE_HZ, color=color, alpha=0.15, lw=0, label=label if i == 0 else None)


CV_NOTE = ("leave-one-trial-out: for each trial, every free parameter is chosen from the registry's grid by the "
           "lowest mean total RMSE on the other trials, and that choice is scored on the trial left out; the "
           "table is the mean of those held-out scores")


def _code_version(name: str) -> str:
    """A digest of the code whose output --cache keeps for filter ``name``: its module, its registry entry (defaults
    and grid), the shared helpers and the metric (so a change to one filter leaves the others' results valid)."""
    spec = registry.FILTERS[name]
    own = Path(inspect.getfile(spec.cls))
    h = hashlib.sha1()
    for f in (own, Path(common.__file__), Path(broad.__file__), Path(quaternion.__file__)):
        h.update(f.read_bytes())
    h.update(json.dumps([spec.defaults, spec.grid], sort_keys=True, default=str).encode())  # its registry entry
    return h.hexdigest()[:16]


def _cv_job(args):
    """Every (filter, grid point) on one trial; results from the cache where present."""
    path, tasks, seconds, cache, versions = args

    trial = None
    out = []
    for name, point in tasks:
        key = hashlib.sha1(json.dumps([versions[name], Path(path).name, Path(path).stat().st_size, seconds, name,
                                       sorted(point.items())], default=str).encode()).hexdigest()
        cached = Path(cache) / f"{key}.json" if cache else None
        if cached is not None and cached.exists():
            out.append(json.loads(cached.read_text()))
            continue
        if trial is None:
            trial = broad.load_trial(path)
            if seconds:
                trial = trial.seconds(0.0, seconds)
            if not _scored(trial):
                return Path(path).stem, None  # nothing the metric scores (only scored results are cached)
        try:
            r = run_filter(name, trial, **point)
            r = {"errors": r["errors"], "us_per_sample": r["us_per_sample"]}
        except peers.PeerMissing as e:
            r = {"missing": str(e)}
        if cached is not None and "errors" in r:
            cached.parent.mkdir(parents=True, exist_ok=True)
            cached.write_text(json.dumps(r))
        out.append(r)
    return Path(path).stem, out


def cross_validate(paths, names, seconds=None, jobs=1, cache=None, progress=None) -> dict:
    """The score matrix of every filter's grid on every trial (computed once), then leave-one-trial-out."""
    tasks = [(n, p) for n in names for p in registry.FILTERS[n].grid_points()]
    versions = {n: _code_version(n) for n in names}
    jobs_list = [(str(p), tasks, seconds, cache, versions) for p in paths]
    rows = {}
    if jobs > 1 and len(paths) > 1:
        with multiprocessing.get_context("spawn").Pool(min(jobs, len(paths))) as pool:
            for tname, res in pool.imap(_cv_job, jobs_list):
                rows[tname] = res
                if progress:
                    progress(tname)
    else:
        for j in jobs_list:
            tname, res = _cv_job(j)
            rows[tname] = res
            if progress:
                progress(tname)
    left_out = [t for t, r in rows.items() if r is None]
    rows = {t: r for t, r in rows.items() if r is not None}
    if len(rows) < 2:
        raise ValueError(f"--cv needs two trials with a movement phase and the optical reference"
                         f"{f' in their first {seconds:g} s' if seconds else ''}; {len(rows)} of {len(rows) + len(left_out)} "
                         "have one" + (" (a longer --seconds scores more)" if seconds else ""))
    trials = list(rows)
    doc = {"cv": {}, "note": CV_NOTE, "trials": trials, "left_out": left_out}
    for name in names:
        idx = [i for i, (n, _) in enumerate(tasks) if n == name]
        points = [tasks[i][1] for i in idx]
        missing = [rows[t][i]["missing"] for t in trials for i in idx if "missing" in rows[t][i]]
        if missing:
            doc.setdefault("missing", {})[name] = missing[0]
            continue
        scores = [[rows[t][i]["errors"] for i in idx] for t in trials]
        us = [[rows[t][i]["us_per_sample"] for i in idx] for t in trials]
        res = crossval.leave_one_out(trials, scores)
        defaults = ({k: v for k, v in factory.make(name, 1.0 / RATE_HZ).settings.items() if k in points[0]}
                    if registry.grid(name) else {})
        doc["cv"][name] = {
            "mean": res.mean,
            "us_per_sample": float(np.mean([us[k][f.choice] for k, f in enumerate(res.folds)])),
            "grid": {k: list(v) for k, v in registry.grid(name).items()},
            "folds": [{"trial": f.trial, "choice": points[f.choice], "errors": f.errors} for f in res.folds],
            "all_trials_choice": points[res.all_trials_choice],
            "in_sample": res.in_sample,
            "defaults": defaults,
            "scores": {"points": points, "total": [[e["total"] for e in row] for row in scores]},
        }
        spec = registry.FILTERS[name]
        if spec.structures and len(trials) >= 3:
            keys = [spec.structure_of(p) for p in points]
            order = sorted(set(keys), key=keys.index)
            folds, s_all, g_all, figs = crossval.nested(trials, scores, [order.index(k) for k in keys])
            nest = doc["cv"][name]["nested"] = {
                "structures": [dict(k) for k in order],
                "mean": {m: float(np.mean([f.errors[m] for f in folds])) for m in crossval.METRICS},
                "folds": [{"trial": f.trial, "structure": dict(order[f.structure]), "choice": points[f.choice],
                           "errors": f.errors} for f in folds],
                "all_trials_structure": dict(order[s_all]),
                "structure_loo": figs,  # each structure's leave-one-out figure over all trials
                "all_trials_choice": points[g_all],
            }
            # the flat leave-one-out above chose among structures and parameters alike; the nested figure is the
            # filter's figure (its structure chosen on held-out data too)
            doc["cv"][name]["flat_mean"] = doc["cv"][name]["mean"]
            doc["cv"][name]["mean"] = nest["mean"]
            doc["cv"][name]["folds"] = nest["folds"]
            doc["cv"][name]["all_trials_choice"] = nest["all_trials_choice"]
    if "vqf" in doc["cv"]:
        ref = doc["cv"]["vqf"]["mean"]["total"]
        for v in doc["cv"].values():
            v["ratio_to_vqf"] = v["mean"]["total"] / ref
    return doc


def format_cv(doc: dict) -> str:
    cv = doc["cv"]
    out = [f"leave-one-trial-out over {len(doc['trials'])} trials: held-out RMSE (°), ratio to vqf, µs per sample"]
    cols = ("total", "heading", "inclination", "ratio_to_vqf", "us_per_sample")
    rows = {n: dict(v["mean"], ratio_to_vqf=v.get("ratio_to_vqf"), us_per_sample=v["us_per_sample"])
            for n, v in cv.items()}
    out.append(_fmt_table("", rows, cols).lstrip("\n"))
    out.append("")
    out.append("choices per fold (trial left out: parameters chosen on the others):")
    for n, v in cv.items():
        if not v["grid"]:
            out.append(f"  {n}: no free parameters (published defaults)")
            continue
        out.append(f"  {n} (grid {', '.join(f'{k}={vals}' for k, vals in v['grid'].items())}):")
        for f in v["folds"]:
            c = ", ".join(f"{k}={x}" for k, x in f["choice"].items())
            out.append(f"    {f['trial'].split('_', 1)[0]}: {c}  → {f['errors']['total']:.2f}")
    out.append("")
    out.append("chosen on all trials (what the registry's defaults should be; its in-sample mean is optimistic):")
    for n, v in cv.items():
        if not v["grid"]:
            continue
        c = ", ".join(f"{k}={x}" for k, x in v["all_trials_choice"].items())
        same = all(v["defaults"].get(k) == x for k, x in v["all_trials_choice"].items())
        flag = "= the registry's defaults" if same else f"DIFFERS from the registry's defaults {v['defaults']}"
        out.append(f"  {n}: {c} (in-sample {v['in_sample']['total']:.2f}°) {flag}")
    for n, msg in doc.get("missing", {}).items():
        out.append(f"  {n}: skipped: {msg}")
    out.append("")
    out.append(doc["note"])
    return "\n".join(out)


def run(args) -> int:
    directory = Path(args.trials) if args.trials else broad_dir()
    try:
        paths = broad.trial_paths(directory)
    except broad.BroadMissing as e:
        print(f"sphere eval: {e}", file=sys.stderr)
        return 2
    if args.only:
        want = [w.strip() for w in args.only.split(",") if w.strip()]
        paths = [p for p in paths if p.stem in want or p.stem.split("_", 1)[0] in want]
        if not paths:
            print(f"sphere eval: no trial matches --only {args.only}", file=sys.stderr)
            return 2
    default_names = list(registry.OURS) + ["vqf"] if args.cv else list(registry.ALL)
    names = [n.strip() for n in args.filters.split(",")] if args.filters else default_names
    bad = [n for n in names if n not in registry.ALL]
    if bad:
        print(f"sphere eval: unknown filter(s) {', '.join(bad)}; known: {', '.join(registry.ALL)}", file=sys.stderr)
        return 2
    print(f"running {', '.join(names)} on {len(paths)} trial(s) from {directory} ...", file=sys.stderr)
    if args.cache and not args.cv:
        print("sphere eval: --cache keeps --cv results; add --cv or leave --cache out", file=sys.stderr)
        return 2
    if args.cv:
        if len(paths) < 2:
            print("sphere eval: --cv needs at least two trials (it leaves one out at a time)", file=sys.stderr)
            return 2
        if args.plot:
            print("sphere eval: --plot draws one plain run; run it without --cv", file=sys.stderr)
            return 2
        if args.cache:
            try:
                Path(args.cache).mkdir(parents=True, exist_ok=True)
                probe = Path(args.cache) / ".write-test"
                probe.write_text("")
                probe.unlink()
            except OSError as e:
                print(f"sphere eval: cannot keep results in --cache {args.cache} ({e.strerror or e}); "
                      "give a writable folder or leave --cache out", file=sys.stderr)
                return 2
        try:
            doc = cross_validate(paths, names, seconds=args.seconds, jobs=args.jobs, cache=args.cache,
                                 progress=_trial_progress(len(paths)))
        except ValueError as e:
            print(f"sphere eval: {e}", file=sys.stderr)
            return 2
        if doc["left_out"]:
            print(f"sphere eval: left out {', '.join(doc['left_out'])}: no movement phase with the optical reference "
                  f"in the first {args.seconds:g} s (a longer --seconds scores them)", file=sys.stderr)
        print(format_cv(doc))
        if args.json:
            Path(args.json).write_text(json.dumps(doc, indent=2, default=_json_default))
            print(f"wrote {args.json}", file=sys.stderr)
        return 0
    try:
        results = evaluate(paths, names, seconds=args.seconds, jobs=args.jobs, keep_errors=bool(args.plot),
                           progress=_trial_progress(len(paths)))
    except ValueError as e:
        print(f"sphere eval: {e}", file=sys.stderr)
        return 2
    unscored = [t for t, r in results.items() if r is None]
    results = {t: r for t, r in results.items() if r is not None}
    if unscored:
        where = (f"in the first {args.seconds:g} s (a longer --seconds scores them)" if args.seconds
                 else "in the whole trial")
        print(f"sphere eval: left out {', '.join(unscored)}: no movement phase with the optical reference {where}"
              if results else f"sphere eval: no trial has a movement phase with the optical reference {where}",
              file=sys.stderr)
        if not results:
            return 2
    doc = summarise(results, names, trial_groups(directory))
    print(format_report(doc, quiet=args.quiet))
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=2, default=_json_default))
        print(f"wrote {args.json}", file=sys.stderr)
    if args.plot:
        for p in write_plots(Path(args.plot), doc, results):
            print(f"wrote {p}", file=sys.stderr)
    return 0


def _json_default(o):
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, float) and not math.isfinite(o):
        return None
    return str(o)
