"""`sphere bench NAME`: benchmarks that print figures (one module per benchmark in sphere.bench)."""

from __future__ import annotations

import importlib
import pkgutil

from sphere import bench

HELP = "run a benchmark and print its figures"


def add_arguments(p) -> None:
    sub = p.add_subparsers(dest="benchmark", metavar="NAME", required=True)
    for info in sorted(pkgutil.iter_modules(bench.__path__), key=lambda i: i.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"sphere.bench.{info.name}")
        bp = sub.add_parser(info.name.replace("_", "-"), help=module.HELP, description=module.HELP)
        module.add_arguments(bp)
        bp.set_defaults(_bench=module.run)


def run(args) -> int:
    return args._bench(args)
