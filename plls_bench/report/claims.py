"""What the paper lacks: statistics for every return comparison (IQM and mean with 95% CIs,
probability of improvement) and the "paper vs suite" table of every quantitative claim.

Each claim in ``results/paper/claims.csv`` names a ``kind`` (how the suite measures it, one
function below), a ``rule`` and ``threshold`` (what counts as reproducing it) and the least
``min_budget`` and x range (``needs_x``) at which it can be judged. The verdict reads the suite's
95% CI: entirely on the claim's side -> reproduced, entirely on the other -> not reproduced,
straddling -> inconclusive; below the budget or range -> not run at this budget. A comparison
that ``requires`` a baseline check (another row: the baseline reaches a published number, or beats
the random policy) is not made while that check is not reproduced, or is itself not made
(:func:`~plls_bench.report.verdicts.gate_all`).

Stochastic quantities need :data:`~plls_bench.report.matched.MIN_TRIALS` finished trials (per arm),
and two arms are compared on the evaluations every finished trial of both reaches
(:mod:`plls_bench.report.matched`); the budget column says at which x.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

from plls_bench.config import BUDGET_NAMES
from plls_bench.metrics import POLICIES
from plls_bench.records.layout import partial_iteration
from plls_bench.report.base import Entry, Options, Output
from plls_bench.report.claim_values import (budget_text, mean_estimate, param_count, repr_mse, steps_to_goal,
                                            study_metric)
from plls_bench.report.efficiency import fmt_convergence, parameter_counts
from plls_bench.report.load import Runs
from plls_bench.report.matched import Matched, NotJudged, at_text, finished_counts, matched, require_trials
from plls_bench.report.returns import DEFAULT_X_AXIS, Curves, convergence, load_curves
from plls_bench.report.stats import CURVE_RESAMPLES, ahead_from, bootstrap_ci, probability_of_improvement
from plls_bench.report.tables import NA, Table, fmt, fmt_ci, read_paper
from plls_bench.report.sweep_claim import sweep_best
from plls_bench.report.verdicts import (NOT_MADE, NOT_RUN, RULES, VERDICTS, Estimate, Judged, gate_all, rule_text,
                                        verdict)

BUDGET_ORDER = BUDGET_NAMES  # ordered from the smallest profile up
SCORES = ("final", "auc")  # p_improvement's per-trial score: the final return, or the mean over the curve


# --------------------------------------------------------------------------- measurements
def _policy(claim: dict[str, str]) -> str:
    """The test returns a curve claim reads: a ``param`` that is, or ends in ``:``, a policy of
    POLICIES ("final:stochastic": sampled actions); the deterministic policy otherwise (D20)."""
    last = claim["param"].rpartition(":")[2]
    return last if last in POLICIES else "deterministic"


def _curves(runs: Runs, name: str, claim: dict[str, str]) -> Curves:
    policy = _policy(claim)
    curves = load_curves(runs, runs.experiment(name), name, claim["x_axis"] or DEFAULT_X_AXIS, policy)
    if not curves.n:
        raise NotJudged(f"no evaluations of {name}" + ("" if policy == "deterministic" else f" with {policy} returns"))
    return curves


def convergence_point(runs: Runs, claim: dict[str, str]) -> Estimate:
    """Stochastic (a mean curve over trials): needs MIN_TRIALS finished trials, judged on the
    evaluations all of them reach."""
    curves = _curves(runs, claim["experiment"], claim)
    counts = finished_counts(curves)
    require_trials(counts, budget_text(runs, claim["experiment"], n=counts))
    result = convergence(curves, curves.finished_seeds())
    if result is None:
        raise NotJudged(f"no evaluation that every finished trial of {claim['experiment']} reaches")
    budget = f"{budget_text(runs, claim['experiment'], n=[result.n])}, {at_text(curves, result.last_x)}"
    return Estimate(result.x, result.ci, fmt_convergence(result), budget, reach=result.last_x)


def _pair(runs: Runs, claim: dict[str, str]) -> tuple[Matched, str]:
    """Both methods' finished trials (MIN_TRIALS each: every pair statistic is stochastic) on the
    evaluations they all reach, and the budget text saying where they are judged."""
    a, b = _curves(runs, claim["experiment"], claim), _curves(runs, claim["baseline"], claim)
    counts = finished_counts(a, b)
    require_trials(counts, budget_text(runs, claim["experiment"], claim["baseline"], n=counts))
    pair = matched(a, b, runs=runs)
    return pair, f"{budget_text(runs, claim['experiment'], claim['baseline'], n=pair.counts)}, {pair.at}"


def ahead_point(runs: Runs, claim: dict[str, str]) -> Estimate:
    """x from which A's mean return stays above B's; inf if A is not ahead at the end."""
    pair, budget = _pair(runs, claim)
    grid, (a, b) = pair.grid, pair.values

    def stat(x: np.ndarray, y: np.ndarray) -> float:
        index = ahead_from(x.mean(axis=0), y.mean(axis=0))
        return math.inf if index is None else float(grid[index])

    value = stat(a, b)
    ci = bootstrap_ci([a, b], stat, n_resamples=CURVE_RESAMPLES, vectorized=False)
    text = "not ahead at the end" if math.isinf(value) else f"ahead from {fmt(value)}"
    return Estimate(value, (float(ci[0]), float(ci[1])), text + _ci_text(ci), budget, reach=float(grid[-1]))


def std_gap(runs: Runs, claim: dict[str, str]) -> Estimate:
    """Mean over evaluations with x >= ``from_x`` of std(B) - std(A) across trials."""
    pair, budget = _pair(runs, claim)
    grid, (a, b) = pair.grid, pair.values
    keep = grid >= float(claim["from_x"] or 0)
    if not keep.any():
        raise NotJudged(f"no evaluations at or after {claim['from_x']}")

    def stat(x: np.ndarray, y: np.ndarray) -> float:
        return float(np.mean(y[:, keep].std(axis=0, ddof=1) - x[:, keep].std(axis=0, ddof=1)))

    value = stat(a, b)
    low, high = (float(v) for v in bootstrap_ci([a, b], stat, n_resamples=CURVE_RESAMPLES, vectorized=False))
    return Estimate(value, (low, high), fmt_ci(value, (low, high)), budget, reach=float(grid[-1]))


def p_improvement(runs: Runs, claim: dict[str, str]) -> Estimate:
    """P(A > B) over trials' ``final`` returns (at the largest common evaluation, not each arm's
    own last) or ``auc`` (mean return over the common evaluations); ``final:stochastic`` reads
    the sampled-action returns of the same test episodes."""
    pair, budget = _pair(runs, claim)
    score = claim["param"].partition(":")[0]
    x, y = ((m[:, -1] if score == "final" else m.mean(axis=1)) for m in pair.values)
    value, ci = probability_of_improvement(x, y)
    text = f"{fmt_ci(value, ci, 3)} ({claim['param']}: {fmt(float(np.mean(x)))} vs {fmt(float(np.mean(y)))})"
    return Estimate(value, ci, text, budget, reach=float(pair.grid[-1]))


def final_return(runs: Runs, claim: dict[str, str]) -> Estimate:
    """Mean over finished trials of the final evaluation's mean return of the ``param`` policy (a
    baseline checked against a published number), at the last evaluation all of them reach.
    Stochastic: needs MIN_TRIALS finished trials."""
    curves = _curves(runs, claim["experiment"], claim)
    counts = finished_counts(curves)
    try:
        require_trials(counts, budget_text(runs, claim["experiment"], n=counts))
    except NotJudged as short:
        raise NotJudged(f"{short}{_finals_so_far(curves)}", short.budget) from None
    arm = matched(curves, runs=runs)
    budget = f"{budget_text(runs, claim['experiment'], n=arm.counts)}, {arm.at}"
    return mean_estimate([float(v) for v in arm.values[0][:, -1]], "trial", budget)


def _finals_so_far(curves: Curves) -> str:
    """The final returns of the trials that did finish, so a row short of trials still shows what
    the evidence says so far: " (final returns 0.73, 9.4 at 100,000 env steps)"; "" if none."""
    if not curves.finished_seeds().any():
        return ""
    arm = matched(curves)
    return f" (final returns {', '.join(fmt(float(v)) for v in arm.values[0][:, -1])} {arm.at})"


def _ci_text(ci: tuple[np.ndarray, np.ndarray]) -> str:
    low, high = float(ci[0]), float(ci[1])
    return "" if math.isnan(low) else f" [{fmt(low)}, {'never' if math.isinf(high) else fmt(high)}]"


KINDS: dict[str, Callable[[Runs, dict[str, str]], Estimate]] = {
    "repr_mse": repr_mse, "param_count": param_count, "steps_to_goal": steps_to_goal,
    "convergence": convergence_point, "ahead_from": ahead_point, "std_gap": std_gap,
    "p_improvement": p_improvement, "study": study_metric, "final_return": final_return,
    "sweep_best": sweep_best,
}


def judge(runs: Runs, claim: dict[str, str]) -> Judged:
    """(estimate, verdict, reason, budget text) for one claim row."""
    budgets = {n: _run_budget(runs, n, claim["kind"]) for n in (claim["experiment"], claim["baseline"]) if n}
    if None in budgets.values():  # every arm without a run is named, so the row says all that is missing
        return None, NOT_RUN, "; ".join(_no_runs_reason(runs, n) for n, b in budgets.items() if b is None), None
    for name, budget in budgets.items():
        if BUDGET_ORDER.index(budget) < BUDGET_ORDER.index(claim["min_budget"]):
            return None, NOT_RUN, f"{name} ran at budget {budget}; judged from budget {claim['min_budget']} up", None
    try:
        est = KINDS[claim["kind"]](runs, claim)
    except NotJudged as err:
        return None, NOT_RUN, str(err), err.budget
    if claim["needs_x"] and est.reach < float(claim["needs_x"]):
        axis = claim["x_axis"] or DEFAULT_X_AXIS
        return est, NOT_RUN, f"runs reach {axis} {fmt(est.reach)} < {fmt(float(claim['needs_x']))}", est.budget
    low, high = est.ci if not math.isnan(est.ci[0]) else (est.value, est.value)
    high_t = float(claim["threshold_high"]) if claim["threshold_high"] else math.nan
    if not math.isnan(est.ci[0]):
        basis = " (95% CI)"
    else:  # a count is exact; anything else from one trial or model has no interval
        basis = "" if claim["kind"] == "param_count" else " (one value: no CI)"
    reason = f"suite value {rule_text(claim)}{basis}"
    return est, verdict(claim["rule"], low, high, float(claim["threshold"]), high_t), reason, est.budget


def _run_budget(runs: Runs, name: str, kind: str) -> str | None:
    """The budget ``name`` ran at; for a parameter count, an unfinished trial's partial record will do."""
    budget = runs.experiment(name).budget
    if budget is None and kind == "param_count":  # the trial parameter_counts reads them from
        counts = parameter_counts(runs, runs.experiment(name))
        budget = counts.trial.cfg("budget.name") if counts else None
    return budget


def _no_runs_reason(runs: Runs, name: str) -> str:
    """Why ``name`` has no trial to judge: none ran, or its trials are unfinished partial records
    (named with the iteration each stopped at, so the table shows how far the evidence has got)."""
    partial = runs.partial_trials(name)
    if not partial:
        return f"no runs of {name}"
    where = [f"seed {t.seed}" + ("" if (at := partial_iteration(t.path)) is None else f" at iteration {at}")
             for t in partial]
    return f"no finished runs of {name}; unfinished, in partial records: {', '.join(where)}"


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _param_problems(row: dict[str, str]) -> list[str]:
    """A return claim's ``param``: ``final`` or ``auc``, optionally ``:<policy>``, for
    p_improvement; a policy for final_return. Other kinds' params name models, fields or files."""
    score, _, policy = row["param"].partition(":")
    valid = {"p_improvement": score in SCORES and policy in ("", *POLICIES),
             "final_return": row["param"] in POLICIES}.get(row["kind"], True)
    return [] if valid else [f"param {row['param']!r} (expected {'/'.join(SCORES)}[:policy] or a policy, "
                             f"policies {', '.join(POLICIES)})"]


def read_claims(paper_dir: Path) -> list[dict[str, str]]:
    """``claims.csv``, checked so that a typo fails loudly naming the row."""
    rows = read_paper(paper_dir, "claims")
    names = {row["claim"] for row in rows}
    for line, row in enumerate(rows, 2):
        allowed = {"kind": tuple(KINDS), "rule": RULES, "min_budget": BUDGET_ORDER}
        problems = [f"{key} {row[key]!r}" for key, values in allowed.items() if row[key] not in values]
        numbers = ("threshold", "threshold_high", "paper_value", "paper_pm", "from_x", "needs_x")
        problems += [f"{key} {row[key]!r} (not a number)" for key in numbers
                     if (row[key] or key == "threshold") and not _is_number(row[key])]
        problems += _param_problems(row)
        if row["requires"] and (row["requires"] == row["claim"] or row["requires"] not in names):
            problems.append(f"requires {row['requires']!r} (the claim text of another row)")
        if problems:
            raise ValueError(f"{paper_dir / 'claims.csv'} line {line}: unknown {', '.join(problems)}")
    _check_chains(rows, paper_dir)
    return rows


def _check_chains(rows: list[dict[str, str]], paper_dir: Path) -> None:
    """Baseline checks may chain (a row's ``requires`` row requires another), but never back to a row
    already on the chain: its verdict would wait on itself."""
    requires = {row["claim"]: row["requires"] for row in rows}
    for line, row in enumerate(rows, 2):
        chain, at = [row["claim"]], row["requires"]
        while at:
            if at in chain:
                raise ValueError(f"{paper_dir / 'claims.csv'} line {line}: requires {row['requires']!r} leads back "
                                 f"to {at!r} (a cycle of baseline checks)")
            chain.append(at)
            at = requires[at]


def claims_table(runs: Runs, entry: Entry, opts: Options) -> Output:
    """The "paper vs suite" table: every claim of ``claims.csv`` with the suite's value and verdict."""
    rows, records = [], []
    claims = read_claims(opts.paper_dir)
    judged = {claim["claim"]: judge(runs, claim) for claim in claims}
    final = gate_all(claims, judged)
    for claim in claims:
        est, _, _, budget = judged[claim["claim"]]
        outcome, reason = final[claim["claim"]]
        rows.append([claim["claim"], claim["paper"], est.text if est else NA, budget or NA,
                     outcome, reason, claim["source"]])
        records.append({"claim": claim["claim"], "entry": claim["entry"], "kind": claim["kind"],
                        "requires": claim["requires"],
                        "paper": claim["paper"], "paper_value": claim["paper_value"],
                        "paper_pm": claim["paper_pm"], "suite_value": est.value if est else None,
                        "ci_low": est.ci[0] if est else None, "ci_high": est.ci[1] if est else None,
                        "suite": est.text if est else None, "budget": budget,
                        "verdict": outcome, "reason": reason, "rule": claim["rule"],
                        "threshold": claim["threshold"], "source": claim["source"]})
    counts = pd.Series([r["verdict"] for r in records]).value_counts()
    shown = [v for v in VERDICTS if v != NOT_MADE or v in counts]  # "0 not made" would only be noise
    summary = ", ".join(f"{counts.get(v, 0)} {v}" for v in shown)
    caption = (f"{len(records)} claims: {summary}. A verdict reads the suite's 95% bootstrap CI (percentile, "
               "fixed seed): entirely on the claim's side of its threshold = reproduced, entirely on the other "
               "side = not reproduced, across it = inconclusive; claims need the budget and x range named in "
               "results/paper/claims.csv. A comparison whose baseline fails its own check (the row it "
               "requires) is not made. Probabilities of improvement follow rliable (Agarwal et al., 2021).")
    table = Table(f"{entry.ref}. {entry.title}", caption,
                  ["Claim", "Paper", "Suite [95% CI]", "Budget (trials)", "Verdict", "Rule", "Source"],
                  rows, pd.DataFrame(records))
    judged = sum(r["suite_value"] is not None for r in records)
    return Output(table=table, trials={"claims with a suite value": judged}, empty=judged == 0)
