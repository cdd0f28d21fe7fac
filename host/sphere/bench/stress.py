"""The stress traces (sphere.fusion.stress: magnets parked, passing and attached, fast turns then rest, fast turns
while shaking; known truth, many seeds) through the daemon's filters side by side, as ratios to VQF.

    sphere bench stress [--seeds N] [--first SEED] [--kinds K1,K2] [--filters sphere,vqf] [--no-mag]

Per kind: the mean over the seeds of each filter's total RMSE (BROAD's metric, every sample after the opening rest;
heading and inclination beside it), the ratio of the means to VQF's and the worst per-seed ratio. ``--no-mag`` runs
the filters without the magnetometer, as the daemon does by default (``[orientation] use_mag = false``): the heading
then only integrates the gyro, so the ratios are of the inclination RMSE. The filters run as
the registry builds them (the same settings as `sphere eval` and the daemon). Seeds from 1000 by default: seeds
below were used to check the generator, none to choose anything.
"""

from __future__ import annotations

import argparse

import numpy as np

from sphere import argtypes
from sphere.fusion import registry
from sphere.fusion.stress import KINDS, SECONDS, score, trace

HELP = "stress traces (magnets, fast turns then rest, shaking): the daemon's filters as ratios to VQF"


def _kinds():
    return KINDS


def _filters():
    return registry.FILTERS


def add_arguments(p) -> None:
    p.add_argument("--seeds", type=argtypes.at_least_one, default=30, help="seeds per kind (default 30)")
    p.add_argument("--first", type=lambda t: argtypes.count(t, 0), default=1000, help="first seed (default 1000)")
    p.add_argument("--kinds", type=argtypes.names_of(_kinds, "stress kind"), default=list(KINDS),
                   help="comma-separated (default: all)")
    p.add_argument("--filters", type=argtypes.names_of(_filters, "filter"), default=["sphere", "vqf"],
                   help="registry names (default sphere,vqf)")
    p.add_argument("--no-mag", action="store_true", help="without the magnetometer (the daemon's default); ratios of "
                   "the inclination")


def scores(kinds, seeds, filters, mag: bool = True) -> dict:
    """{kind: {filter: [errors per seed]}}: each filter as the registry builds it on each (kind, seed) trace."""
    out = {}
    for kind in kinds:
        out[kind] = {f: [] for f in filters}
        for seed in seeds:
            tr = trace(kind, seed)
            for f in filters:
                out[kind][f].append(score(tr, f, mag=mag))
    return out


def format_scores(res: dict, seeds, ref: str = "vqf", metric: str = "total") -> str:
    filters = list(next(iter(res.values())))
    lines = [f"stress traces: {len(seeds)} seeds ({seeds[0]}-{seeds[-1]}) per kind, {SECONDS:g} s each; mean total "
             f"RMSE (°) over the seeds (heading / inclination); ratio = mean {metric} / {ref}'s, worst = the largest "
             "per-seed ratio"]
    head = f"{'kind':<17}" + "".join(f"{f:>25}" for f in filters)
    others = [f for f in filters if f != ref] if ref in filters else []
    head += "".join(f"{'ratio ' + f:>16}{'worst':>7}" for f in others)
    lines.append(head)
    for kind, by in res.items():
        m = {f: {k: float(np.mean([e[k] for e in by[f]])) for k in ("total", "heading", "inclination")}
             for f in filters}
        row = f"{kind:<17}" + "".join(f"{m[f]['total']:>9.2f} ({m[f]['heading']:5.2f} / {m[f]['inclination']:5.2f})"
                                      for f in filters)
        for f in others:
            worst = max(a[metric] / b[metric] for a, b in zip(by[f], by[ref]))
            row += f"{m[f][metric] / m[ref][metric]:>16.2f}{worst:>7.2f}"
        lines.append(row)
    return "\n".join(lines)


def run(args) -> int:
    seeds = list(range(args.first, args.first + args.seeds))
    if args.no_mag:
        print("without the magnetometer (the daemon's default): heading from the gyro alone; ratios of the inclination")
    print(format_scores(scores(args.kinds, seeds, args.filters, mag=not args.no_mag), seeds,
                        metric="inclination" if args.no_mag else "total"))
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m sphere.bench.stress", description=__doc__.split("\n\n")[0])
    add_arguments(p)
    return run(p.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
