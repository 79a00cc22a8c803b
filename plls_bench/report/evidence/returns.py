"""Return curves from ``metrics/eval.jsonl``: per-trial curves on a chosen x axis, aligned across
trials, and the per-trial scores (final return, mean over the curve) that statistics compare."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from plls_bench.core.metric_rows import EvalRow, parallel_envs
from plls_bench.pipeline.runner_registry import iteration_label
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.stats import CURVE_RESAMPLES, align, bootstrap_ci, complete, convergence_index
from plls_bench.report.evidence.trials import Experiment, Trial
from plls_bench.rundirs.run_dir import STATUS_DONE

X_AXES = ("iteration", "env_steps", "wall_s", "env_steps_per_env")
DEFAULT_X_AXIS = "iteration"  # the paper's axis, PPO iterations (docs/decisions.md#d1)


@dataclass
class Curves:
    """One method's evaluation curves: ``values`` ``(n_trials, P)`` on ``grid`` ``(P,)``, NaN where
    a trial has no evaluation (it stopped earlier, or its rows were lost)."""

    label: str
    experiment: Experiment
    x_axis: str
    seeds: list[int] = field(default_factory=list)
    grid: np.ndarray = field(default_factory=lambda: np.zeros(0))
    values: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    env_steps: dict[float, float] = field(default_factory=dict)  # env steps at each x the trials logged

    @property
    def n(self) -> int:
        return len(self.seeds)

    def complete_seeds(self) -> np.ndarray:
        """Mask of the trials that reach this method's last grid point (finished curves)."""
        return ~np.isnan(self.values[:, -1]) if self.n else np.zeros(0, dtype=bool)

    def finished_seeds(self) -> np.ndarray:
        """Mask of the trials whose run finished (status done): comparisons count only these."""
        done = {t.seed for t in self.experiment.trials if t.state == STATUS_DONE}
        return np.array([seed in done for seed in self.seeds], dtype=bool)


def x_label(exp: Experiment, x_axis: str) -> str:
    """Axis label naming what one unit is for this experiment's runner."""
    if x_axis == "iteration":
        return iteration_label(exp.cfg)
    return {"env_steps": "environment steps (frames)", "wall_s": "wall-clock time (s)",
            "env_steps_per_env": "environment steps per parallel env"}[x_axis]


def load_curves(runs: Runs, exp: Experiment, label: str, x_axis: str = DEFAULT_X_AXIS,
                policy: str = "deterministic") -> Curves:
    """Every trial of ``exp`` with at least one usable evaluation of ``policy`` (in
    :data:`~plls_bench.core.metric_rows.POLICIES`), on one grid."""
    curves = Curves(label, exp, x_axis)
    pairs = []
    for trial in exp.trials:
        x, y = _trial_curve(runs, exp, trial, x_axis, curves.env_steps, policy)
        if len(x):
            curves.seeds.append(trial.seed)
            pairs.append((x, y))
    curves.grid, curves.values = align(pairs, interpolate=x_axis == "wall_s")
    return curves


def _trial_curve(runs: Runs, exp: Experiment, trial: Trial, x_axis: str, env_steps: dict[float, float],
                 policy: str = "deterministic") -> tuple[np.ndarray, np.ndarray]:
    """A trial's (x, mean return of ``policy``) points; ``env_steps`` gains the env steps at each x."""
    points: dict[float, float] = {}
    skipped = duplicated = 0
    scale = float(parallel_envs(trial.cfg)) if x_axis == "env_steps_per_env" else 1.0
    source_key = "env_steps" if x_axis == "env_steps_per_env" else x_axis
    for record in runs.records(exp, trial, "eval"):
        row = EvalRow.from_record(record)
        x = None if row is None else row.x(source_key)
        value = None if row is None else row.mean_return(policy)
        if x is None or value is None:
            skipped += 1
            continue
        duplicated += (x / scale) in points
        points[x / scale] = value
        if (steps := row.x("env_steps")) is not None:
            env_steps[x / scale] = steps
    if skipped:
        runs.gap(exp, trial, f"metrics/eval.jsonl: {skipped} row(s) without {source_key} or {policy} returns skipped")
    if duplicated:
        runs.gap(exp, trial, f"metrics/eval.jsonl: {duplicated} duplicate evaluation(s); last kept")
    xs = np.array(sorted(points))
    return xs, np.array([points[x] for x in xs])


# --------------------------------------------------------------------------- scores
@dataclass(frozen=True)
class Scores:
    """Per-trial scores ``(n,)`` of one method: ``final`` (mean return over the last evaluations
    compared, the claims' final_tail) and ``auc`` (mean return over the evaluations compared), over its
    finished trials."""

    label: str
    seeds: tuple[int, ...]
    final: np.ndarray
    auc: np.ndarray
    last_x: float


# --------------------------------------------------------------------------- convergence
@dataclass(frozen=True)
class Convergence:
    """Where the mean curve converged (Table 3's rule, :func:`stats.convergence_index`) on one
    x axis, with its bootstrap CI over trials; ``inf`` = not converged within the budget."""

    x: float
    ci: tuple[float, float]
    n: int
    last_x: float


def convergence(curves: Curves, keep: np.ndarray | None = None) -> Convergence | None:
    """Convergence of the mean curve over the trials ``keep`` selects (default: those reaching the
    method's last evaluation, as for :func:`scores`; a shorter trial cannot bend the tail), on the
    evaluations all of them reach. None without data."""
    if not curves.n:
        return None
    grid, (values,) = complete(curves.grid, curves.values[curves.complete_seeds() if keep is None else keep])
    if not len(grid):
        return None

    def at(matrix: np.ndarray) -> float:
        index = convergence_index(matrix.mean(axis=0))
        return math.inf if index is None else float(grid[index])

    low, high = bootstrap_ci([values], at, n_resamples=CURVE_RESAMPLES, vectorized=False)
    return Convergence(at(values), (float(low), float(high)), len(values), float(grid[-1]))
