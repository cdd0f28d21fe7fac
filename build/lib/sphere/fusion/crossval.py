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
