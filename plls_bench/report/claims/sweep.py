"""Claim kind ``sweep_best``: the preset's own value of a declared sweep performs the best (Sec.
5.2: "the dimensionality of the action representation e is set as N_e = 32, which performs the
best"). ``param`` names the sweep (``conf/sweep/<param>.yaml``), or ``<sweep>:stochastic`` to read the
same test episodes with sampled actions (docs/decisions.md#d20; the deterministic policy otherwise).

For every other value v, the base value's final returns (mean over the last ``final_tail``
evaluations every finished trial of every arm reaches) are compared with v's under the protocol
(:func:`~plls_bench.report.evidence.protocol.compare_arms`). "Best" is an intersection: every comparison
must find the base better, so the row's comparison is the least significant of them (the
intersection-union test needs no correction among its parts); one that finds some v better
stands for the row instead, as does the comparison with the fewest trials while any has fewer than
the protocol's minimum (the hardest of those: the smallest standardised effect in the base's favour,
so the power table plans for the comparison that needs the most trials). rliable's P(base > v) is
shown beside each, and the budget names every arm that pools commits or devices.
"""
from __future__ import annotations

import math

from plls_bench.pipeline.sweeps import load_sweep
from plls_bench.report.claims.compare import arm_mix, first_trials_text
from plls_bench.report.claims.values import policy_of
from plls_bench.report.evidence.claim_settings import ClaimSettings
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.matched import NotJudged, finished_counts, require_trials
from plls_bench.report.evidence.protocol import B_BETTER, TOO_FEW, Comparison, compare_arms, tail_mean
from plls_bench.report.evidence.returns import DEFAULT_X_AXIS
from plls_bench.report.evidence.stats import probability_of_improvement
from plls_bench.report.evidence.sweep_arms import matched_arms, sweep_arms
from plls_bench.report.evidence.table_formats import NA, fmt, fmt_ci
from plls_bench.report.evidence.verdicts import Estimate


def sweep_best(runs: Runs, claim: dict[str, str], settings: ClaimSettings) -> Estimate:
    """The base value against each other value on final return; see the module docstring."""
    sweep = load_sweep(claim["param"].partition(":")[0])
    arms = sweep_arms(runs, sweep, claim["x_axis"] or DEFAULT_X_AXIS, policy_of(claim))
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
    require_trials(counts, budget, minimum=1)  # fewer than min_n: described, not tested
    planned = settings.planned(claim["claim"])
    pair = matched_arms(runs, arms, first=planned)
    final = [tail_mean(v, settings.final_tail) for v in pair.values]
    margin = settings.comparisons[claim["claim"]].margin if claim["claim"] in settings.comparisons else None
    compared = [(arms[i].label, compare_arms(final[base], final[i], margin=margin, alpha=settings.alpha,
                                             min_n=settings.min_n), *probability_of_improvement(final[base], final[i]))
                for i in range(len(arms)) if i != base]
    against = [c for _, c, _, _ in compared if c.outcome == B_BETTER]
    too_few = [c for _, c, _, _ in compared if c.outcome == TOO_FEW]
    row = max(too_few, key=_weakness) if too_few else against[0] if against else max(
        (c for _, c, _, _ in compared), key=_weakness)
    key = sweep.key.rsplit(".", 1)[-1]
    text = f"{key}={sweep.base} vs v: " + "; ".join(
        f"v={label} {fmt(c.mean_a)} vs {fmt(c.mean_b)}, {c.text}, rliable P = {fmt_ci(p, ci, 3)}"
        for label, c, p, ci in compared)
    mixes = "".join(f"; {m}" for m in (arm_mix(runs, a.exp, f"{key}={a.label}") for a in arms) if m)
    where = f"{budget}, {pair.at}{first_trials_text(counts, pair.counts, planned)}{mixes}"
    return Estimate(row.effect, (math.nan, math.nan), text, where, reach=float(pair.grid[-1]), comparison=row)


def _weakness(comparison: Comparison) -> tuple[bool, float]:
    """How far a comparison is from finding the base better: an untested one (too few trials)
    before any tested one, ordered by its smaller standardised effect; a tested one by its p. The
    row stands for its hardest part."""
    if not math.isnan(comparison.p):
        return False, comparison.p
    spread = math.hypot(comparison.sd_a, comparison.sd_b)
    if not spread > 0:  # no spread (or one trial): only the sign of the effect speaks
        return True, -math.copysign(1e300, comparison.effect)
    return True, -comparison.effect / spread
