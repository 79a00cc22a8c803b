"""Claim kind ``sweep_best``: the preset's own value of a declared sweep performs the best (Sec.
5.2: "the dimensionality of the action representation e is set as N_e = 32, which performs the
best"). ``param`` names the sweep (``conf/sweep/<param>.yaml``); rule ``greater_than`` 0.5.

For every other value v, P(base > v) on the final return (at the evaluation x every finished trial
of every arm reaches) with its 95% stratified-bootstrap CI. The estimate is the smallest P and its
"CI" the smallest lower and smallest upper bound over the other values, so the ``greater_than 0.5``
rule reads: every CI above 0.5 -> reproduced; some CI at or below 0.5, i.e. some CI of
P(v > base) = 1 - P(base > v) at or above 0.5 (ties count half) -> not reproduced; else
inconclusive. Every arm needs MIN_TRIALS finished trials at the base runs' budget.
"""
from __future__ import annotations

import numpy as np

from plls_bench.report.matched import NotJudged, finished_counts, require_trials
from plls_bench.report.returns import DEFAULT_X_AXIS
from plls_bench.report.stats import probability_of_improvement
from plls_bench.report.sweep_arms import matched_arms, scores, sweep_arms
from plls_bench.report.tables import NA, fmt, fmt_ci
from plls_bench.report.load import Runs
from plls_bench.report.verdicts import Estimate
from plls_bench.sweeps import load_sweep


def sweep_best(runs: Runs, claim: dict[str, str]) -> Estimate:
    """P(base value > each other value) on final return; see the module docstring."""
    sweep = load_sweep(claim["param"])
    arms = sweep_arms(runs, sweep, claim["x_axis"] or DEFAULT_X_AXIS)
    budgets = [a.exp.budget for a in arms]
    base = next(i for i, a in enumerate(arms) if a.value == sweep.base)
    counts = finished_counts(*(a.curves for a in arms))
    budget = f"{'/'.join(sorted({b or NA for b in budgets}))} ({' + '.join(map(str, counts))} trials)"
    missing = [a.label for a in arms if not a.curves.n]
    if missing:
        raise NotJudged(f"no runs of {sweep.key} = {', '.join(missing)} "
                        f"(python -m plls_bench.reproduce --sweep {sweep.name})", budget)
    other = [f"{a.label} at {b}" for a, b in zip(arms, budgets) if b != budgets[base]]
    if other:
        raise NotJudged(f"arms at another budget than the preset's own runs ({budgets[base]}): "
                        f"{', '.join(other)}", budget)
    require_trials(counts, budget)
    pair = matched_arms(runs, arms)
    final = scores(pair)["final"]
    comparisons = [(arms[i].label, *probability_of_improvement(final[base], final[i]))
                   for i in range(len(arms)) if i != base]
    points = np.array([p for _, p, _ in comparisons])
    lows, highs = (np.array([ci[k] for _, _, ci in comparisons]) for k in (0, 1))
    text = f"P({sweep.key.rsplit('.', 1)[-1]}={sweep.base} > v): " + "; ".join(
        f"v={label} {fmt_ci(p, ci, 3)}" for label, p, ci in comparisons)
    text += f" (final: {', '.join(f'{a.label}: {fmt(float(np.mean(f)))}' for a, f in zip(arms, final))})"
    return Estimate(float(points.min()), (float(lows.min()), float(highs.min())), text,
                    f"{budget}, {pair.at}", reach=float(pair.grid[-1]))
