"""Another revision of this repository's host package, for the benchmarks' ``--against REV`` (side by side)."""

from __future__ import annotations

import os
import statistics
import subprocess

from sphere.errors import SphereError


class RevisionError(SphereError):
    """``--against`` named something that is not a revision here (or git cannot give it): one line, exit 2."""


def tree_of(rev: str, into: str) -> str:
    """``host/`` of revision ``rev`` of the repository this file is in, extracted into ``into``."""
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    git = ["git", "-C", repo]
    try:
        ok = subprocess.run(git + ["rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}"],
                            capture_output=True, text=True)
    except FileNotFoundError:
        raise RevisionError("--against needs git on PATH") from None
    if ok.returncode != 0:
        raise RevisionError(f"--against {rev}: not a commit of the repository at {repo} (this needs a git checkout "
                            "of the project; `git log --oneline` lists the revisions)")
    archive = subprocess.run(git + ["archive", "--format=tar", ok.stdout.strip(), "host"], capture_output=True)
    if archive.returncode != 0:
        raise RevisionError(f"--against {rev}: git archive failed: {archive.stderr.decode(errors='replace').strip()}")
    subprocess.run(["tar", "-x", "-C", into], input=archive.stdout, check=True)
    return os.path.join(into, "host")


def take_turns(sides: dict[str, str], pairs: int, run_one, describe) -> dict[str, list]:
    """``pairs`` runs of every side (name → its ``host/``), the sides taking turns at going first (pair 1 in the
    given order, pair 2 reversed, …) so that a machine warming up or getting busier weighs on both alike.
    ``run_one(name, host_dir)`` measures one run; ``describe(result)`` is printed after it. Returns name → runs."""
    runs: dict[str, list] = {name: [] for name in sides}
    for i in range(pairs):
        for name in list(sides) if i % 2 == 0 else list(reversed(sides)):
            result = run_one(name, sides[name])
            runs[name].append(result)
            print(f"  pair {i + 1}/{pairs} {name:>12}: {describe(result)}", flush=True)
    return runs


def medians(runs: dict[str, list], this: str, other: str, get) -> tuple[float, float, float]:
    """The median of ``get(run)`` over each side's runs, and their ratio this / other."""
    a = statistics.median(get(r) for r in runs[this])
    b = statistics.median(get(r) for r in runs[other])
    return a, b, a / b
