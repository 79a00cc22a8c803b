"""Claim kinds that read one arm's return curves against a number (threshold rows): the final
return against a published anchor or the random policy (``final_return``), and where the mean
curve converges (``convergence``). Intervals are valid at the row's n: a Student t interval of the
mean, or an order-statistic interval of the median (distribution-free) where a trial may never
converge; never the percentile bootstrap at a handful of trials."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy import stats

from plls_bench.core.metric_rows import EvalRow
from plls_bench.report.claims.compare import arm_mix
from plls_bench.report.claims.values import budget_text, policy_of
from plls_bench.report.evidence.claim_settings import ClaimSettings, dispersion_text
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.matched import Matched, NotJudged, at_text, finished_counts, matched, require_trials
from plls_bench.report.evidence.protocol import one_sample_p, t_interval, tail_mean, welch
from plls_bench.report.evidence.returns import DEFAULT_X_AXIS, Curves, load_curves
from plls_bench.report.evidence.stats import CONVERGENCE_WINDOW, complete, convergence_index
from plls_bench.report.evidence.table_formats import fmt
from plls_bench.report.evidence.verdicts import Estimate

REPO_ROOT = Path(__file__).resolve().parents[3]


def _curves(runs: Runs, claim: dict[str, str]) -> Curves:
    name, policy = claim["experiment"], policy_of(claim)
    curves = load_curves(runs, runs.experiment(name), name, claim["x_axis"] or DEFAULT_X_AXIS, policy)
    if not curves.n:
        raise NotJudged(f"no evaluations of {name}" + ("" if policy == "deterministic" else f" with {policy} returns"))
    return curves


def _mix(runs: Runs, curves: Curves) -> str:
    mix = arm_mix(runs, curves.experiment)
    return f"; {mix}" if mix else ""


# --------------------------------------------------------------------------- final return
def final_return(runs: Runs, claim: dict[str, str], settings: ClaimSettings) -> Estimate:
    """Mean over finished trials of each trial's final return (the mean over the last
    ``final_tail`` evaluations all of them reach) with its t-interval; the single last evaluation
    is shown as a sensitivity reading. A random-policy gate adds its per-seed and one-sample tests."""
    curves = _curves(runs, claim)
    counts = finished_counts(curves)
    try:
        require_trials(counts, budget_text(runs, claim["experiment"], n=counts), minimum=settings.threshold_min_n)
    except NotJudged as short:
        raise NotJudged(f"{short}{_finals_so_far(curves)}", short.budget) from None
    arm = matched(curves, runs=runs)
    budget = f"{budget_text(runs, claim['experiment'], n=arm.counts)}, {arm.at}{_mix(runs, curves)}"
    finals = tail_mean(arm.values[0], settings.final_tail)
    low, high = t_interval(finals, 1 - settings.alpha)
    tail = min(settings.final_tail, len(arm.grid))
    text = (f"{fmt(float(finals.mean()))} ± {fmt(float(finals.std(ddof=1)))} ({len(finals)} trials, final = mean of "
            f"the last {tail} evaluations), t-interval [{fmt(low)}, {fmt(high)}]")
    last = arm.values[0][:, -1]
    last_low, last_high = t_interval(last, 1 - settings.alpha)
    text += f"; single last evaluation {fmt(float(last.mean()))} [{fmt(last_low)}, {fmt(last_high)}]"
    if claim["claim"] in settings.anchors:
        text += f"; {dispersion_text(*settings.anchors[claim['claim']])}"
    unreadable = None
    if claim["claim"] in settings.random_gates:
        gate, unreadable = _random_gate(runs, claim, settings, curves, arm, finals)
        text += f"; {gate}"
    return Estimate(float(finals.mean()), (low, high), text, budget, unreadable=unreadable)


def _finals_so_far(curves: Curves) -> str:
    """The final returns of the trials that did finish, so a row short of trials still shows what
    the evidence says so far: " (final returns 0.73, 9.4 at 100,000 env steps)"; "" if none."""
    if not curves.finished_seeds().any():
        return ""
    arm = matched(curves)
    return f" (final returns {', '.join(fmt(float(v)) for v in arm.values[0][:, -1])} {arm.at})"


def _reference_returns(path: Path, key: str) -> np.ndarray:
    import json
    node = json.loads(path.read_text())
    for part in key.split("."):
        node = node[part]
    return np.asarray(node, dtype=float)


def _tail_episodes(runs: Runs, curves: Curves, seed: int, xs: np.ndarray) -> np.ndarray:
    """The test-episode returns of trial ``seed`` at the evaluations ``xs`` (its claim's policy)."""
    trial = next(t for t in curves.experiment.trials if t.seed == seed)
    wanted, episodes = set(float(x) for x in xs), []
    for record in runs.records(curves.experiment, trial, "eval"):
        row = EvalRow.from_record(record)
        if row is not None and row.x(curves.x_axis) is not None and float(row.x(curves.x_axis)) in wanted:
            episodes += row.episode_returns
    return np.asarray(episodes, dtype=float)


def _random_gate(runs: Runs, claim: dict[str, str], settings: ClaimSettings, curves: Curves, arm: Matched,
                 finals: np.ndarray) -> tuple[str, str | None]:
    """Every seed's tail test episodes must beat the random policy's (one-sided Welch at alpha):
    (text, the seeds that do not, or None). The seed means are read by the row's t-interval against
    the random policy's upper CI bound (claims.csv), a stricter one-sample test than the one-sided
    one-sample t-test against its mean shown beside it."""
    file, key = settings.random_gates[claim["claim"]]
    try:
        random = _reference_returns(REPO_ROOT / file, key)
    except (OSError, KeyError, TypeError, ValueError) as err:
        raise NotJudged(f"no random-policy episodes at {file}:{key} ({err})") from None
    xs = arm.grid[-settings.final_tail:]
    seeds = [s for s, done in zip(curves.seeds, curves.finished_seeds()) if done]
    failing, parts = [], []
    for seed in seeds:
        own = _tail_episodes(runs, curves, seed, xs)
        t, df, _ = welch(own, random)
        p = float(stats.t.sf(t, df))
        parts.append(f"seed {seed} {fmt(float(own.mean()))} over {len(own)} episodes, p = {p:.2g}")
        failing += [seed] if p > settings.alpha else []
    p_means = one_sample_p(finals, float(random.mean()), "greater")
    text = (f"random policy {fmt(float(random.mean()))} over {len(random)} episodes; per seed (one-sided Welch): "
            f"{'; '.join(parts)}; seed means against its mean, one-sided one-sample t p = {p_means:.2g}")
    if failing:
        return text, (f"seed(s) {', '.join(map(str, failing))} do not beat the random policy on their own test "
                      f"episodes at alpha {settings.alpha:g}")
    return text, None


# --------------------------------------------------------------------------- convergence
def median_interval(values: np.ndarray, coverage: float) -> tuple[float, float, float] | None:
    """Distribution-free interval of the median of ``values`` ``(n,)`` from order statistics:
    (low, high, its exact coverage) with the narrowest symmetric pair covering at least
    ``coverage``; None when n is too small for any pair to reach it."""
    x = np.sort(np.asarray(values, dtype=float))
    n = len(x)
    for k in range(n // 2, 0, -1):  # [x_(k), x_(n+1-k)] covers with 1 - 2 P(Binom(n, 1/2) <= k - 1)
        exact = 1 - 2 * stats.binom.cdf(k - 1, n, 0.5)
        if exact >= coverage:
            return float(x[k - 1]), float(x[n - k]), float(exact)
    return None


def least_trials(coverage: float) -> int:
    """Fewest trials whose extreme order statistics bound the median with ``coverage``."""
    n = 2
    while 1 - 2 * 0.5 ** n < coverage:
        n += 1
    return n


def _x_text(x: float) -> str:
    return "never" if math.isinf(x) else fmt(x)


def convergence_point(runs: Runs, claim: dict[str, str], settings: ClaimSettings) -> Estimate:
    """Each finished trial's convergence point (Table 3's rule on its own curve; inf: never) on the
    evaluations all of them reach; the row reads their median in an order-statistic interval. A
    claimed x later than the detector can see (it needs CONVERGENCE_WINDOW evaluations after the
    point) cannot be read at this budget."""
    curves = _curves(runs, claim)
    counts = finished_counts(curves)
    require_trials(counts, budget_text(runs, claim["experiment"], n=counts), minimum=1)
    grid, (values,) = complete(curves.grid, curves.values[curves.finished_seeds()])
    if not len(grid):
        raise NotJudged(f"no evaluation that every finished trial of {claim['experiment']} reaches")
    points = np.array([math.inf if (i := convergence_index(v)) is None else float(grid[i]) for v in values])
    mean_curve = convergence_index(values.mean(axis=0))
    budget = (f"{budget_text(runs, claim['experiment'], n=[len(values)])}, {at_text(curves, float(grid[-1]))}"
              f"{_mix(runs, curves)}")
    visible = float(grid[-CONVERGENCE_WINDOW]) if len(grid) >= CONVERGENCE_WINDOW else -math.inf
    shown = ", ".join(_x_text(p) for p in points)
    text = (f"per trial {shown}; mean curve {'never' if mean_curve is None else fmt(float(grid[mean_curve]))}; "
            f"the detector sees convergence up to {fmt(visible)}")
    claimed = float(claim["paper_value"] or claim["threshold"])
    if claimed > visible and claim["rule"] != "at_least":
        raise NotJudged(f"the detector sees convergence only up to {fmt(visible)} at this budget (it needs "
                        f"{CONVERGENCE_WINDOW} evaluations after the point); the claim's {fmt(claimed)} lies beyond",
                        budget)
    bounds = median_interval(points, settings.median_coverage)
    if bounds is None:
        raise NotJudged(f"needs {least_trials(settings.median_coverage)} trials for a {settings.median_coverage:.0%} "
                        f"interval of the median convergence point; has {len(points)} ({text})", budget)
    low, high, exact = bounds
    median = float(np.median(points))
    text = (f"median {_x_text(median)} [{_x_text(low)}, {_x_text(high)}] ({exact:.1%} order-statistic interval); "
            f"{text}")
    return Estimate(median, (low, high), text, budget, reach=float(grid[-1]))
