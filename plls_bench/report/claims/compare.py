"""Claim kinds that compare two arms' trials, decided by :mod:`plls_bench.report.evidence.protocol`: "A beats
B" (``p_improvement``: final or mean-over-the-curve return), "A has the smaller spread"
(``std_gap``: Brown-Forsythe deviations) and "A is ahead from x" (``ahead_from``: the mean return
over the evaluations from x on). rliable's probability of improvement and the bootstrap band stay
in the row as description. The verdict is read from the comparison (:func:`comparison_verdict`),
after Holm's correction over the primary rows (``claims.claims_table``)."""
from __future__ import annotations

import math

import numpy as np

from plls_bench.report.claims.values import budget_text, policy_of
from plls_bench.report.evidence.claim_settings import ClaimSettings
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.looks import INTERIM_LOOK, look
from plls_bench.report.evidence.matched import Matched, NotJudged, finished_counts, matched, require_trials
from plls_bench.report.evidence.protocol import (
    A_BETTER,
    B_BETTER,
    EQUIVALENT,
    TOO_FEW,
    Comparison,
    compare_arms,
    tail_mean,
)
from plls_bench.report.evidence.returns import DEFAULT_X_AXIS, Curves, load_curves
from plls_bench.report.evidence.stats import ahead_from, probability_of_improvement
from plls_bench.report.evidence.table_formats import fmt, fmt_ci
from plls_bench.report.evidence.trials import Experiment
from plls_bench.report.evidence.verdicts import (
    INCONCLUSIVE,
    INTERIM,
    NOT_REPRODUCED,
    NOT_RUN,
    NOT_SOLVED,
    REPRODUCED,
    Estimate,
)


def arm_mix(runs: Runs, exp: Experiment, name: str | None = None) -> str:
    """The commits and devices one arm's pooled trials ran on, when they are not all one:
    "carracing_ppo pools seed 0 (cpu, 3b4e22a), seeds 1, 2 (cuda, 914a039)" (``name``, default the
    experiment's, names the arm); "" otherwise. A trial resumed on another machine or commit names
    each ("seed 5 (cpu, 0922f05 + ab61694)"). Trials are pooled only when their configs agree apart
    from the seed and the device (:func:`plls_bench.report.evidence.identity.pooling_identity`)."""
    groups: dict[tuple[str, str], list[int]] = {}
    for trial in exp.trials:
        groups.setdefault(_where_it_ran(runs.json(exp, trial, "provenance.json") or {}), []).append(trial.seed)
    if len(groups) <= 1:
        return ""
    parts = [f"seed{'s' if len(s) > 1 else ''} {', '.join(map(str, s))} ({d}, {c})" for (d, c), s in groups.items()]
    return f"{name or exp.name} pools {'; '.join(parts)}"


def _where_it_ran(provenance: dict) -> tuple[str, str]:
    """The devices and commits of every start of one trial, in order ("cpu", "0a0e90c + ab61694"):
    a trial stopped and resumed later may have run on two machines or at two commits."""
    starts = provenance.get("starts") or [provenance]
    devices = [str(s.get("device_resolved") or "unknown device").split(":")[0] for s in starts]
    commits = [str(s.get("git_sha") or "unknown commit")[:7] for s in starts]
    return " + ".join(dict.fromkeys(devices)), " + ".join(dict.fromkeys(commits))


def _curves(runs: Runs, name: str, claim: dict[str, str]) -> Curves:
    policy = policy_of(claim)
    curves = load_curves(runs, runs.experiment(name), name, claim["x_axis"] or DEFAULT_X_AXIS, policy)
    if not curves.n:
        raise NotJudged(f"no evaluations of {name}" + ("" if policy == "deterministic" else f" with {policy} returns"))
    return curves


def pair_of(runs: Runs, claim: dict[str, str], settings: ClaimSettings) -> tuple[Matched, str]:
    """Both arms' finished trials (of seeds 0 to the planned n - 1) on the evaluations
    they all reach, and the budget text saying where they are judged, which trials enter, and which
    commits and devices each arm mixes."""
    a, b = _curves(runs, claim["experiment"], claim), _curves(runs, claim["baseline"], claim)
    counts = finished_counts(a, b)
    require_trials(counts, budget_text(runs, claim["experiment"], claim["baseline"], n=counts), minimum=1)
    planned = settings.planned(claim["claim"])
    pair = matched(a, b, runs=runs, first=planned)
    mixes = [m for m in (arm_mix(runs, c.experiment) for c in (a, b)) if m]
    budget = f"{budget_text(runs, claim['experiment'], claim['baseline'], n=pair.counts)}, {pair.at}"
    return pair, budget + first_trials_text(counts, pair.counts, planned) + "".join(f"; {m}" for m in mixes)


def first_trials_text(finished: list[int], judged: list[int], planned: int | None) -> str:
    """"; each arm's seeds 0-5 of 6 + 7 finished trials (the planned n, 6)" where a row leaves trials out."""
    if finished == judged:
        return ""
    return (f"; each arm's seeds 0-{(planned or 1) - 1} of {' + '.join(map(str, finished))} finished trials "
            f"(the planned n, {planned})")


def _unsolved(runs: Runs, claim: dict[str, str], settings: ClaimSettings, pair: Matched) -> str | None:
    """Why neither arm solves the task (no trial's final return reaches the task's declared
    criterion), or None."""
    task = str(runs.experiment(claim["experiment"]).cfg("env.name", ""))
    criterion = settings.solved_at.get(task)
    if criterion is None:
        return None
    finals = [tail_mean(v, settings.final_tail) for v in pair.values]
    if any((f >= criterion).any() for f in finals):
        return None
    best = max(float(f.max()) for f in finals)
    return f"no trial of either arm reaches {task}'s solve criterion {fmt(criterion)} (best final return {fmt(best)})"


def _compare(a: np.ndarray, b: np.ndarray, claim: dict[str, str], settings: ClaimSettings,
             direction: str = "greater") -> Comparison:
    margin = settings.comparisons[claim["claim"]].margin if claim["claim"] in settings.comparisons else None
    return compare_arms(a, b, direction=direction, margin=margin, alpha=settings.alpha, min_n=settings.min_n)


def _poi_text(x: np.ndarray, y: np.ndarray) -> str:
    value, ci = probability_of_improvement(x, y)
    few = f", {len(x) * len(y) + 1} possible values at {len(x)} + {len(y)} trials" if min(len(x), len(y)) < 10 else ""
    return f"rliable P(A > B) = {fmt_ci(value, ci, 3)}{few}"


def p_improvement(runs: Runs, claim: dict[str, str], settings: ClaimSettings) -> Estimate:
    """A > B on each trial's ``final`` return (mean over the last ``final_tail`` evaluations both arms
    reach; the single last one is a sensitivity reading) or ``auc`` (mean over the curve)."""
    pair, budget = pair_of(runs, claim, settings)
    score = claim["param"].partition(":")[0]
    tail = settings.final_tail
    x, y = ((tail_mean(m, tail) if score == "final" else m.mean(axis=1)) for m in pair.values)
    comp = _compare(x, y, claim, settings)
    label = (f"final, mean of the last {min(tail, len(pair.grid))} evaluations" if score == "final"
             else "mean over the curve")
    text = f"{fmt(comp.mean_a)} vs {fmt(comp.mean_b)} ({label}); {comp.text}"
    if score == "final":
        last = _compare(pair.values[0][:, -1], pair.values[1][:, -1], claim, settings)
        text += f"; single last evaluation {fmt(last.mean_a)} vs {fmt(last.mean_b)}, {last.text}"
    text += f"; {_poi_text(x, y)}"
    return Estimate(comp.effect, (math.nan, math.nan), text, budget, reach=float(pair.grid[-1]), comparison=comp,
                    unreadable=_unsolved(runs, claim, settings, pair))


def dispersion_scores(x: np.ndarray) -> np.ndarray:
    """Brown-Forsythe's absolute deviations from the median, ``(n,)``: comparing two arms' spread
    is comparing these (Levene's test with the median)."""
    x = np.asarray(x, dtype=float)
    return np.abs(x - np.median(x))


def std_gap(runs: Runs, claim: dict[str, str], settings: ClaimSettings) -> Estimate:
    """A has the smaller spread across trials of the mean return over the evaluations with x >=
    ``from_x``: Brown-Forsythe (each trial's absolute deviation from its arm's median) compared
    under the protocol; std(B) - std(A) shown beside it."""
    pair, budget = pair_of(runs, claim, settings)
    keep = pair.grid >= float(claim["from_x"] or 0)
    if not keep.any():
        raise NotJudged(f"no evaluations at or after {claim['from_x']}")
    x, y = (m[:, keep].mean(axis=1) for m in pair.values)
    comp = _compare(dispersion_scores(x), dispersion_scores(y), claim, settings, direction="less")
    sd_a, sd_b = (float(np.std(v, ddof=1)) if len(v) > 1 else math.nan for v in (x, y))
    gap = sd_b - sd_a
    text = (f"std {fmt(sd_a)} vs {fmt(sd_b)} (gap {fmt(gap)}) of the mean "
            f"return from x = {fmt(float(pair.grid[keep][0]))}; Brown-Forsythe: {comp.text}")
    return Estimate(gap, (math.nan, math.nan), text, budget, reach=float(pair.grid[-1]), comparison=comp,
                    unreadable=_unsolved(runs, claim, settings, pair))


def ahead_point(runs: Runs, claim: dict[str, str], settings: ClaimSettings) -> Estimate:
    """A ahead of B from about x (the claim's threshold): A's mean return over the evaluations from
    the threshold on beats B's under the protocol; the x from which A's mean curve stays above B's
    is shown beside it."""
    pair, budget = pair_of(runs, claim, settings)
    keep = pair.grid >= float(claim["threshold"])
    if not keep.any():
            raise NotJudged(f"no evaluations at or after {claim['threshold']}")
    x, y = (m[:, keep].mean(axis=1) for m in pair.values)
    comp = _compare(x, y, claim, settings)
    index = ahead_from(pair.values[0].mean(axis=0), pair.values[1].mean(axis=0))
    point = "not ahead at the end" if index is None else f"ahead from {fmt(float(pair.grid[index]))}"
    text = (f"{point}; mean return from x = {fmt(float(pair.grid[keep][0]))}: {fmt(comp.mean_a)} vs "
            f"{fmt(comp.mean_b)}, {comp.text}")
    return Estimate(comp.effect, (math.nan, math.nan), text, budget, reach=float(pair.grid[-1]), comparison=comp,
                    unreadable=_unsolved(runs, claim, settings, pair))


def comparison_verdict(claim: str, est: Estimate, settings: ClaimSettings, family: int | None) -> tuple[str, str]:
    """The verdict of a comparison row and its reason; ``family``: the number of primary rows its
    p was Holm-corrected over (None: a sensitivity reading, decided on its own p)."""
    comp = est.comparison
    assert comp is not None
    if est.unreadable:
        return NOT_SOLVED, est.unreadable
    if comp.outcome == TOO_FEW:
        return NOT_RUN, f"needs {settings.min_n} per arm, has {comp.n_a} + {comp.n_b}"
    planned = settings.planned(claim)
    if look(comp.n_a, comp.n_b, planned, settings.min_n) == INTERIM_LOOK:
        reading = {A_BETTER: "in the claim's direction", B_BETTER: "against the claim's direction",
                   EQUIVALENT: "equivalent within the margin"}.get(comp.outcome, "undecided")
        return INTERIM, (f"an interim look at {comp.n_a} + {comp.n_b} of the planned {planned} per arm: "
                         f"its own p = {comp.p:.2g} ({reading}) is not a verdict until then")
    basis = (f"Holm-adjusted p = {comp.p_adjusted:.2g} over {family} primary comparisons" if family
             else f"p = {comp.p:.2g} (a sensitivity reading, outside the Holm family)")
    if comp.outcome == A_BETTER:
        return REPRODUCED, f"{basis} <= {comp.alpha:g}, in the claim's direction"
    if comp.outcome == B_BETTER:
        return NOT_REPRODUCED, f"{basis} <= {comp.alpha:g}, against the claim's direction"
    if comp.outcome == EQUIVALENT:
        margin = fmt(comp.margin or 0.0)
        return NOT_REPRODUCED, f"{basis}; equivalent within ±{margin} (TOST p = {comp.p_equivalence:.2g})"
    need = (f"80% power at the observed effect needs {comp.n_for_power} per arm" if comp.n_for_power
            else "no observed effect to plan for" if not comp.effect else "80% power needs more than 1000 per arm")
    return INCONCLUSIVE, f"{basis} > {comp.alpha:g}; {need}" + (f" (planned: {planned})" if planned else "")
