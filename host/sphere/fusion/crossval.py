"""Leave-one-trial-out choice of a filter's free parameters (pure logic; `sphere eval --cv` feeds it).

The score matrix is computed once: ``scores[t][g]`` = the error dict of grid point g on trial t. Fold k
chooses the grid point with the lowest mean total RMSE over every trial except k and reports that point's
errors on trial k, so no figure comes from a trial its parameters were chosen on. The point chosen on
all trials is what the registry's defaults should be.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CRITERION = "total"
METRICS = ("total", "heading", "inclination")


@dataclass(frozen=True)
class Fold:
    trial: str
    choice: int  # index into the grid, chosen on the other trials
    errors: dict  # the held-out trial's errors with that choice


@dataclass(frozen=True)
class Result:
    folds: list[Fold]
    all_trials_choice: int  # the grid point with the lowest mean over every trial (in-sample)
    in_sample: dict  # mean errors of that point over all trials (optimistic: chosen and scored on them)

    @property
    def mean(self) -> dict:
        """Mean over the held-out trials of each metric (the cross-validated figure)."""
        return {m: float(np.mean([f.errors[m] for f in self.folds])) for m in METRICS}


def best(matrix: np.ndarray, rows) -> int:
    """Index of the grid point with the lowest mean over ``rows``; ties go to the earlier point."""
    return int(np.argmin(matrix[list(rows)].mean(axis=0)))


def leave_one_out(trials: list[str], scores: list[list[dict]]) -> Result:
    """``scores[t][g]``: errors of grid point g on trial t (dicts with :data:`METRICS`)."""
    if len(trials) < 2:
        raise ValueError("leave-one-trial-out needs at least two trials")
    crit = np.array([[s[CRITERION] for s in row] for row in scores], dtype=float)
    n = len(trials)
    folds = []
    for k in range(n):
        g = best(crit, [t for t in range(n) if t != k])
        folds.append(Fold(trials[k], g, dict(scores[k][g])))
    g_all = best(crit, range(n))
    in_sample = {m: float(np.mean([scores[t][g_all][m] for t in range(n)])) for m in METRICS}
    return Result(folds, g_all, in_sample)


@dataclass(frozen=True)
class NestedFold:
    trial: str
    structure: int  # index into the structures, chosen by its inner leave-one-out figure on the other trials
    choice: int  # index into the grid: that structure's best point on the other trials
    errors: dict
    inner: list  # the inner leave-one-out figure of every structure (mean total RMSE over the other trials)


def nested(trials: list[str], scores: list[list[dict]], structure: list[int]) -> tuple[list[NestedFold], int, int, list]:
    """Nested leave-one-trial-out: the structure is chosen the way the parameters are, on held-out data.

    ``structure[g]`` is the structure grid point g belongs to. For each outer trial k: each structure's figure is its
    own leave-one-out (its parameters chosen on all but one of the *other* trials, scored on that one, averaged); the
    structure with the lowest such figure is chosen (ties: the earlier, i.e. simpler, structure), its parameters are
    the best on all the other trials, and that point is scored on trial k. Returns the folds, and the structure and
    point the same rule chooses on all trials (what the registry's defaults should be), with every structure's
    leave-one-out figure over all trials (its parameters chosen without the trial scored)."""
    n = len(trials)
    if n < 3:
        raise ValueError("nested leave-one-trial-out needs at least three trials")
    crit = np.array([[s[CRITERION] for s in row] for row in scores], dtype=float)
    structure = np.asarray(structure)
    groups = sorted(set(structure.tolist()))

    def choose(rows):
        figs = []
        for s in groups:
            cols = np.flatnonzero(structure == s)
            sub = crit[:, cols]
            figs.append(float(np.mean([sub[j, best(sub, [r for r in rows if r != j])] for j in rows])))
        s = groups[int(np.argmin(figs))]
        cols = np.flatnonzero(structure == s)
        return s, int(cols[best(crit[:, cols], rows)]), figs

    folds = []
    for k in range(n):
        s, g, figs = choose([t for t in range(n) if t != k])
        folds.append(NestedFold(trials[k], s, g, dict(scores[k][g]), figs))
    s_all, g_all, figs = choose(list(range(n)))
    return folds, s_all, g_all, figs
