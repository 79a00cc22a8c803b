"""A declared sweep as a figure (the N_e sweep of Sec. 5.2): final return (the mean of the last
``final_tail`` evaluations, as the claims rows read it) and mean return over the curve against the swept
value, mean over trials with the 95% bootstrap CI of the mean, each trial as a dot, the same test
episodes read acting on the policy's mean and sampling actions (docs/decisions.md#d20); beside them
V_a's test MSE against the value under both readings (z sampled, decode(mu)). Returns are compared at
the evaluations every finished trial of every arm reaches."""
from __future__ import annotations

import numpy as np
import pandas as pd

from plls_bench.pipeline.sweeps import load_sweep
from plls_bench.report.evidence.claim_settings import load_settings
from plls_bench.report.evidence.entry_types import BASE_BLUE, PLLS_RED, Entry, Options, Output
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.matched import NotJudged
from plls_bench.report.evidence.stats import summarise
from plls_bench.report.evidence.sweep_arms import MSE_READINGS, Arm, matched_arms, scores, sweep_arms, va_mse
from plls_bench.report.figures.plot import empty_output, new_figure, suptitle

PANELS = {"final": "final return (mean of the last {tail} evaluations)", "mean": "mean return over the curve"}
# The return series: how the test episodes act (a key of plls_bench.core.metric_rows.POLICIES).
READINGS = {"deterministic": "acting on the mean", "stochastic": "sampled actions"}


def _row(panel: str, series: str, arm: Arm, values: np.ndarray, at: str) -> dict:
    """One point of the figure: mean of ``values`` ``(n,)`` with its CI (NaN below 2 values)."""
    s = summarise(values)
    return {"panel": panel, "series": series, "value": arm.value, "variant": arm.exp.variant, "n": s.n,
            "mean": s.mean, "ci_low": s.mean_ci[0], "ci_high": s.mean_ci[1], "at": at,
            "points": " ".join(f"{v:.6g}" for v in values)}


def _return_rows(runs: Runs, arms: list[Arm], series: str, tail: int) -> list[dict]:
    """The return panels' points of one reading, at the evaluations every finished trial reaches;
    the final return is the mean of the last ``tail`` of them."""
    done = [a for a in arms if a.curves.finished_seeds().any()]
    if not done:
        return []
    try:
        pair = matched_arms(runs, done)
    except NotJudged as err:  # no x every arm reaches: returns are not drawn, MSE still is
        runs.gap(done[0].exp, None, f"sweep returns ({series}) not drawn: {err}")
        return []
    return [_row(panel, series, arm, v, pair.at)
            for panel, per_arm in scores(pair, tail).items() for arm, v in zip(done, per_arm)]


def sweep_data(runs: Runs, arms_by_reading: dict[str, list[Arm]], tail: int) -> pd.DataFrame:
    """The tidy data: one row per (panel, series, value); ``arms_by_reading`` maps a return series
    (a value of :data:`READINGS`) to the sweep's arms read that way, the first also giving V_a's MSE;
    ``tail`` is the protocol's ``final_tail``."""
    rows = [row for series, arms in arms_by_reading.items() for row in _return_rows(runs, arms, series, tail)]
    arms = next(iter(arms_by_reading.values()))
    for field, reading in MSE_READINGS.items():
        rows += [_row("va_test_mse", reading, arm, np.array(v), "") for arm in arms if (v := va_mse(runs, arm, field))]
    return pd.DataFrame(rows)


def _draw(ax, frame: pd.DataFrame, color: str, label: str, base: float) -> None:
    x = frame["value"].astype(float).to_numpy()
    mean = frame["mean"].to_numpy()
    low = np.where(np.isnan(frame["ci_low"]), mean, frame["ci_low"])
    high = np.where(np.isnan(frame["ci_high"]), mean, frame["ci_high"])
    ax.errorbar(x, mean, yerr=[mean - low, high - mean], color=color, marker="o", capsize=3, lw=1.4, label=label)
    for value, points in zip(x, frame["points"]):
        ys = [float(p) for p in points.split()]
        ax.scatter([value] * len(ys), ys, color=color, s=10, alpha=0.4, lw=0)
    ax.axvline(base, color="grey", ls=":", lw=1.0)


def sweep_figure(runs: Runs, entry: Entry, opts: Options, *, sweep: str) -> Output:
    """Three panels over the sweep's values: final return and mean return (both readings), V_a test MSE."""
    spec = load_sweep(sweep)
    by_reading = {series: sweep_arms(runs, spec, opts.x_axis, policy) for policy, series in READINGS.items()}
    arms = by_reading[READINGS["deterministic"]]
    name = spec.key.rsplit(".", 1)[-1]
    trials = {f"{name}={a.value}": a.curves.n for a in arms}
    budgets = sorted({b for a in arms if (b := a.exp.budget)})
    title = f"{entry.title} (budget {'/'.join(budgets) or 'none'})"
    tail = load_settings(opts.paper_dir, None).final_tail  # the protocol block, as the claims rows
    data = sweep_data(runs, by_reading, tail)
    if data.empty:
        return empty_output(runs, entry, title)
    fig = new_figure(entry.size)
    axes = fig.subplots(1, 3)
    for ax, (panel, ylabel) in zip(axes, [*((k, v.format(tail=tail)) for k, v in PANELS.items()),
                                             ("va_test_mse", "V_a test MSE")]):
        part = data[data["panel"] == panel]
        for (series, frame), color in zip(part.groupby("series", sort=False), (PLLS_RED, BASE_BLUE)):
            _draw(ax, frame, color, series, float(spec.base))
        ax.set_xscale("log", base=2)
        ax.set_xticks([float(v) for v in spec.values], [str(v) for v in spec.values])
        ax.set_xlabel(f"{name} (dotted: the preset's {spec.base})")
        ax.set_ylabel(ylabel)
        if panel == "va_test_mse" and not part.empty and (part["mean"] > 0).all():
            ax.set_yscale("log")
        if part["series"].nunique() > 1:
            ax.legend(fontsize=8)
        at = part["at"].iloc[0] if not part.empty else ""
        ax.set_title(f"{ylabel}{', ' + at if at else ''}" if not part.empty else f"{ylabel}: no data", fontsize=8)
        ax.grid(alpha=0.3)
    suptitle(fig, entry.ref, title, trials)
    return Output(fig, data, trials=trials)
