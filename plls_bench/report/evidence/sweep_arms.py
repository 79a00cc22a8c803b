"""A declared sweep's arms as the collector reads them (``conf/sweep/<name>.yaml``,
:mod:`plls_bench.pipeline.sweeps`): one arm per value, the preset's own runs for its own value and the
override's variant for every other, and what each arm is scored on.

Scores are per trial on the evaluations that every finished trial of every arm reaches
(:func:`plls_bench.report.evidence.matched.matched`): the final return (the mean of the last
``final_tail`` common evaluations, as the claims rows read it) and the mean return over the common
evaluations. V_a's test MSE per arm comes from the arm's own runs' ``metrics/repr_test.json`` (written
by the ``ppo`` runner for the models it trained on), one value per distinct artifact.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from plls_bench.pipeline.sweeps import Sweep
from plls_bench.report.evidence.load import DEFAULT_VARIANT, Runs
from plls_bench.report.evidence.matched import Matched, matched
from plls_bench.report.evidence.protocol import tail_mean
from plls_bench.report.evidence.returns import Curves, load_curves
from plls_bench.report.evidence.trials import Experiment

# V_a's test MSE under both readings the suite reports (docs/architecture.md, "What each runner writes").
MSE_READINGS = {"test_mse": "z sampled", "test_mse_posterior_mean": "decode(mu)"}


@dataclass
class Arm:
    """One value of the sweep: its runs (``exp``, variant ``default`` for the preset's own value)
    and their return curves."""

    value: Any
    exp: Experiment
    curves: Curves

    @property
    def label(self) -> str:
        return str(self.value)


def sweep_experiments(runs: Runs, sweep: Sweep, values: tuple[Any, ...] | None = None) -> list[tuple[Any, Experiment]]:
    """``(value, runs)`` per value of ``sweep`` (all of them, in its order, unless ``values``): the
    preset's own variant for its base value, the override's variant for every other."""
    return [(value, runs.experiment(sweep.preset, sweep.arm_variant(value) or DEFAULT_VARIANT))
            for value in (sweep.values if values is None else values)]


def sweep_arms(runs: Runs, sweep: Sweep, x_axis: str, policy: str = "deterministic") -> list[Arm]:
    """Every value's arm, in the sweep's order (arms without runs have ``curves.n == 0``), its test
    returns read under ``policy`` (a key of :data:`~plls_bench.core.metric_rows.POLICIES`)."""
    return [Arm(value, exp, load_curves(runs, exp, sweep.override(value), x_axis, policy=policy))
            for value, exp in sweep_experiments(runs, sweep)]


def scores(pair: Matched, tail: int) -> dict[str, list[np.ndarray]]:
    """Per arm, ``final`` ``(n_i,)`` (mean return over the last ``tail`` common evaluations, the
    claims rows' final) and ``mean`` ``(n_i,)`` (mean return over the common evaluations) of each
    finished trial; ``pair.values[i]`` is ``(n_i, P)``."""
    return {"final": [tail_mean(v, tail) for v in pair.values], "mean": [v.mean(axis=1) for v in pair.values]}


def matched_arms(runs: Runs, arms: list[Arm], first: int | None = None) -> Matched:
    """The arms' finished trials (of seeds 0 to ``first`` - 1) on the evaluations all
    of them reach (raises NotJudged)."""
    return matched(*(a.curves for a in arms), runs=runs, first=first)


def va_mse(runs: Runs, arm: Arm, field: str) -> list[float]:
    """V_a's ``field`` (a key of :data:`MSE_READINGS`) per distinct trained V_a of ``arm``'s trials
    (trials sharing an artifact count once); a trial without the file is a gap."""
    values: dict[str, float] = {}
    for trial in arm.exp.trials:
        entry = (runs.json(arm.exp, trial, "metrics/repr_test.json") or {}).get("action")
        if isinstance(entry, dict) and isinstance(entry.get(field), (int, float)) and math.isfinite(entry[field]):
            values.setdefault(str(entry.get("artifact", trial.seed)), float(entry[field]))
    return list(values.values())
