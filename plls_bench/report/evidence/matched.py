"""Fair comparisons for the claims table: how many trials a claim needs, and the evaluations that
every finished trial of every arm reaches.

Two arms are compared where both were measured: each arm's finished trials (status done) are cut
to the evaluation x values present in all of them and in the other arm's (the intersection of their
grids), and "final" means the value at the largest such x, never each arm's own last evaluation.
An arm run to 1,024,000 env steps and one run to 160,000 are compared at 160,000.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import reduce

import numpy as np

from plls_bench.report.evidence.load import MIN_TRIALS, Runs
from plls_bench.report.evidence.looks import planned_seeds
from plls_bench.report.evidence.returns import Curves
from plls_bench.report.evidence.stats import complete
from plls_bench.report.evidence.table_formats import fmt


class NotJudged(Exception):
    """The runs cannot judge this claim (no data, too small a budget, too few trials); the
    message says why, ``budget`` (when known) what the runs hold."""

    def __init__(self, message: str, budget: str | None = None) -> None:
        super().__init__(message)
        self.budget = budget


def require_trials(counts: list[int], budget: str, unit: str = "trials", minimum: int = MIN_TRIALS) -> None:
    """Raise :class:`NotJudged` unless every arm has ``minimum`` ``unit``: "needs 3 trials per arm;
    has 1 + 1"."""
    if min(counts) < minimum:
        per_arm = " per arm" if len(counts) > 1 else ""
        raise NotJudged(f"needs {minimum} {unit}{per_arm}; has {' + '.join(map(str, counts))}", budget)


@dataclass(frozen=True)
class Matched:
    """Finished trials of each arm on their common evaluations: ``values[i]`` is arm i's
    ``(n_i, P)`` on ``grid`` ``(P,)``."""

    grid: np.ndarray
    values: list[np.ndarray]
    at: str  # where they are judged: "at 160,000 env steps (iteration 10)"

    @property
    def counts(self) -> list[int]:
        return [len(v) for v in self.values]


def finished_counts(*arms: Curves) -> list[int]:
    return [int(c.finished_seeds().sum()) for c in arms]


def matched(*arms: Curves, runs: Runs | None = None, first: int | None = None) -> Matched:
    """Every arm's finished trials (of seeds 0 to ``first`` - 1: a row's planned n,
    :mod:`~plls_bench.report.evidence.looks`) cut to the evaluation x values all of them reach; a
    finished trial ending before its arm's last evaluation is a gap in ``runs`` (it pulls the x back)."""
    masks = [planned_seeds(c.finished_seeds(), np.array(c.seeds), first) for c in arms]
    for arm, mask in zip(arms, masks):
        if not mask.any():
            raise NotJudged(f"no finished trials of {arm.experiment.name}")
        if runs is not None:
            _report_short(runs, arm, mask)
    grid = reduce(np.intersect1d, [c.grid for c in arms])
    values = [c.values[m][:, np.searchsorted(c.grid, grid)] for c, m in zip(arms, masks)]
    grid, values = complete(grid, *values)
    if not len(grid):
        reach = "; ".join(f"{c.experiment.name} up to {c.x_axis} {fmt(_last_common(c, m))}"
                          for c, m in zip(arms, masks))
        raise NotJudged(f"no evaluation x that every finished trial of every arm reaches ({reach})")
    return Matched(grid, values, at_text(arms[0], float(grid[-1])))


def _report_short(runs: Runs, curves: Curves, mask: np.ndarray) -> None:
    for seed, short in zip(curves.seeds, mask & ~curves.complete_seeds()):
        if short:
            trial = next(t for t in curves.experiment.trials if t.seed == seed)
            runs.gap(curves.experiment, trial, "curve ends before the method's last evaluation: "
                                               "comparisons are judged where every trial reaches")


def _last_common(curves: Curves, mask: np.ndarray) -> float:
    """The largest x every finished trial of ``curves`` reaches (NaN if none)."""
    grid, _ = complete(curves.grid, curves.values[mask])
    return float(grid[-1]) if len(grid) else float("nan")


def at_text(curves: Curves, x: float) -> str:
    """Where a comparison is judged, in env steps (as budgets are stated) and on its own axis."""
    steps = x if curves.x_axis == "env_steps" else curves.env_steps.get(x)
    if steps is None:
        return f"at {curves.x_axis.replace('_', ' ')} {fmt(x)}"
    if curves.x_axis == "env_steps":
        return f"at {fmt(steps)} env steps"
    return f"at {fmt(steps)} env steps ({curves.x_axis.replace('_', ' ')} {fmt(x)})"
