"""The "paper vs suite" table of every quantitative claim, each decided by the declared protocol.

Each claim in ``results/paper/claims.csv`` names a ``kind`` (how the suite measures it), a ``rule``
and ``threshold`` (what counts as reproducing it) and the least ``min_budget`` and x range
(``needs_x``) at which it can be judged; ``results/paper/claims.yaml`` holds the protocol's
settings and each claim's own (margins, planned trials, solve criteria, readings).

- Comparison rows (two arms) are decided by :mod:`plls_bench.report.evidence.protocol` (Welch's t with its
  permutation p, Holm-corrected over the primary comparison rows, TOST against the claim's margin):
  :func:`plls_bench.report.claims.compare.comparison_verdict`.
- Threshold rows read an interval valid at their n (Student t, or an order-statistic interval of
  a median) against the threshold: entirely on the claim's side -> reproduced, entirely on the
  other -> not reproduced, straddling -> inconclusive.
- Below the budget, range or trials a row needs -> not run at this budget. A comparison row not
  decided yet says what its planned trials cost (:mod:`plls_bench.report.claims.costs`). A comparison that
  ``requires`` a baseline check is not made while that check is not reproduced
  (:func:`~plls_bench.report.evidence.verdicts.gate_all`); nor is one where neither arm solves the task.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import pandas as pd

from plls_bench.config import BUDGET_NAMES
from plls_bench.core.metric_rows import POLICIES
from plls_bench.report.claims.compare import ahead_point, comparison_verdict, p_improvement, std_gap
from plls_bench.report.claims.costs import undecided_cost
from plls_bench.report.claims.levels import convergence_point, final_return
from plls_bench.report.claims.sweep import sweep_best
from plls_bench.report.claims.values import param_count, repr_mse, steps_to_goal, study_metric
from plls_bench.report.evidence.claim_settings import ClaimSettings, check_rows, load_settings
from plls_bench.report.evidence.entry_types import Entry, Options, Output
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.matched import NotJudged
from plls_bench.report.evidence.protocol import adjust, holm
from plls_bench.report.evidence.returns import DEFAULT_X_AXIS
from plls_bench.report.evidence.table_formats import NA, Table, fmt, read_paper
from plls_bench.report.evidence.variant_arms import found_variants
from plls_bench.report.evidence.verdicts import (
    INCONCLUSIVE,
    INTERIM,
    NOT_MADE,
    NOT_REPRODUCED,
    NOT_RUN,
    NOT_SOLVED,
    REPRODUCED,
    RULES,
    VERDICTS,
    Estimate,
    Judged,
    gate_all,
    rule_text,
    verdict,
)
from plls_bench.report.tables.efficiency import parameter_counts
from plls_bench.rundirs.record_layout import partial_iteration

BUDGET_ORDER = BUDGET_NAMES  # ordered from the smallest profile up
SCORES = ("final", "auc")  # p_improvement's per-trial score: the final return, or the mean over the curve


KINDS: dict[str, Callable[[Runs, dict[str, str], ClaimSettings], Estimate]] = {
    "repr_mse": repr_mse, "param_count": param_count, "steps_to_goal": steps_to_goal,
    "convergence": convergence_point, "ahead_from": ahead_point, "std_gap": std_gap,
    "p_improvement": p_improvement, "study": study_metric, "final_return": final_return,
    "sweep_best": sweep_best,
}


def judge(runs: Runs, claim: dict[str, str], settings: ClaimSettings) -> Judged:
    """(estimate, verdict, reason, budget text) for one claim row; a comparison row's verdict on
    its own p (``claims_table`` reads it again at its Holm-corrected p)."""
    budgets = {n: _run_budget(runs, n, claim["kind"]) for n in (claim["experiment"], claim["baseline"]) if n}
    if None in budgets.values():  # every arm without a run is named, so the row says all that is missing
        return None, NOT_RUN, "; ".join(_no_runs_reason(runs, n) for n, b in budgets.items() if b is None), None
    for name, budget in budgets.items():
        if BUDGET_ORDER.index(budget) < BUDGET_ORDER.index(claim["min_budget"]):
            return None, NOT_RUN, f"{name} ran at budget {budget}; judged from budget {claim['min_budget']} up", None
    try:
        est = KINDS[claim["kind"]](runs, claim, settings)
    except NotJudged as err:
        return None, NOT_RUN, str(err), err.budget
    if claim["needs_x"] and est.reach < float(claim["needs_x"]):
        axis = claim["x_axis"] or DEFAULT_X_AXIS
        return est, NOT_RUN, f"runs reach {axis} {fmt(est.reach)} < {fmt(float(claim['needs_x']))}", est.budget
    if est.comparison is not None:
        return (est, *comparison_verdict(claim["claim"], est, settings, None), est.budget)
    if est.unreadable:  # a gate that fails its own tests
        return est, NOT_REPRODUCED, est.unreadable, est.budget
    low, high = est.ci if not math.isnan(est.ci[0]) else (est.value, est.value)
    high_t = float(claim["threshold_high"]) if claim["threshold_high"] else math.nan
    if not math.isnan(est.ci[0]):
        basis = " (95% interval)"
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


VARIANTS_TABLE = "results/tables/variants.md"


def _no_runs_reason(runs: Runs, name: str) -> str:
    """Why ``name`` has no trial to judge: none ran, or its trials are unfinished partial records
    (named with the iteration each stopped at, so the table shows how far the evidence has got)."""
    partial = runs.partial_trials(name)
    if not partial:
        # trials of another config (a former default kept as a variant) are named, never judged here
        counts = {v: len(runs.experiment(name, v).trials) for v in found_variants(runs).get(name, [])}
        elsewhere = [f"{v}: {n}" for v, n in counts.items() if n]
        return f"no runs of {name}" + (f" (finished trials of its variants, in {VARIANTS_TABLE}: "
                                       f"{', '.join(elsewhere)})" if elsewhere else "")
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
    # claims.yaml names only these rows, and every comparison and published anchor among them
    check_rows(load_settings(paper_dir, [row["claim"] for row in rows]), rows, paper_dir)
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


def holm_judged(judged: dict[str, Judged], settings: ClaimSettings) -> dict[str, Judged]:
    """The primary comparison rows (claims.yaml, ``primary``) judged at their planned n, read again at
    their Holm-corrected p; every other row as judged. The family is every primary row claims.yaml
    declares, fixed before the data: a row not yet judged enters at p = 1, so no row's verdict
    weakens when another row's trials arrive (Holm's adjusted p never rises as a raw p falls)."""
    family = [name for name, plan in settings.comparisons.items() if plan.primary]  # settings.family_size rows
    tested = [name for name in family if _judged_at_planned_n(judged[name])]
    adjusted = dict(zip(family, holm([judged[name][0].comparison.p if name in tested else 1.0 for name in family])))
    out = dict(judged)
    for name in tested:
        est = judged[name][0]
        est = replace(est, comparison=adjust(est.comparison, float(adjusted[name])))
        out[name] = (est, *comparison_verdict(name, est, settings, settings.family_size), est.budget)
    return out


def _judged_at_planned_n(judged: Judged) -> bool:
    """A comparison row whose test is a verdict: tested, readable, and neither short of trials nor an
    interim look."""
    est, outcome = judged[0], judged[1]
    return (est is not None and est.comparison is not None and not est.unreadable
            and outcome not in (NOT_RUN, INTERIM))


DECIDED = (REPRODUCED, NOT_REPRODUCED, INCONCLUSIVE)  # verdicts on the data; not run / not made say nothing yet


def reading_summary(settings: ClaimSettings, final: dict[str, tuple[str, str]]) -> str:
    """How many claims read more than one way depend on the reading: at least two of its readings
    have decided verdicts (:data:`DECIDED`) that differ. "Not run" against "not made" is no
    disagreement: such claims are counted apart, as not yet comparable."""
    depends: dict[str, int] = {}
    pending = 0
    for reading, rows in settings.readings:
        decided = [final[row][0] for row in rows if final[row][0] in DECIDED]
        depends[reading] = depends.get(reading, 0) + (len(set(decided)) > 1)
        pending += len(decided) < 2
    per = ", ".join(f"{reading} {n} of {sum(r == reading for r, _ in settings.readings)}"
                    for reading, n in depends.items())
    return (f"{sum(depends.values())} of {len(settings.readings)} claims read more than one way depend on the "
            f"reading, two readings decided ({', '.join(DECIDED)}) and differing ({per}); {pending} are not yet "
            "comparable, fewer than two readings decided")


def claims_table(runs: Runs, entry: Entry, opts: Options) -> Output:
    """The "paper vs suite" table: every claim of ``claims.csv`` with the suite's value and verdict."""
    rows, records = [], []
    claims = read_claims(opts.paper_dir)
    settings = load_settings(opts.paper_dir, [c["claim"] for c in claims])
    judged = holm_judged({claim["claim"]: judge(runs, claim, settings) for claim in claims}, settings)
    final = gate_all(claims, judged)
    for claim in claims:
        est, _, _, budget = judged[claim["claim"]]
        outcome, reason = final[claim["claim"]]
        comp = est.comparison if est else None
        cost = undecided_cost(runs, claim, comp, outcome, settings)
        reason += f"; {cost}" if cost else ""
        rows.append([claim["claim"], claim["paper"], est.text if est else NA, budget or NA,
                     outcome, reason, claim["source"]])
        records.append({"claim": claim["claim"], "entry": claim["entry"], "kind": claim["kind"],
                        "requires": claim["requires"],
                        "paper": claim["paper"], "paper_value": claim["paper_value"],
                        "paper_pm": claim["paper_pm"], "suite_value": est.value if est else None,
                        "ci_low": est.ci[0] if est else None, "ci_high": est.ci[1] if est else None,
                        "test": comp.test if comp else None, "statistic": comp.statistic if comp else None,
                        "p": comp.p if comp else None, "p_adjusted": comp.p_adjusted if comp else None,
                        "n_for_power": comp.n_for_power if comp else None,
                        "suite": est.text if est else None, "budget": budget,
                        "verdict": outcome, "reason": reason, "rule": claim["rule"],
                        "threshold": claim["threshold"], "source": claim["source"]})
    counts = pd.Series([r["verdict"] for r in records]).value_counts()
    shown = [v for v in VERDICTS if v not in (NOT_MADE, NOT_SOLVED) or v in counts]  # "0 not made" is noise
    summary = ", ".join(f"{counts.get(v, 0)} {v}" for v in shown)
    caption = (f"{len(records)} claims: {summary}; {reading_summary(settings, final)}. "
               f"How verdicts are decided: docs/verdicts.md. A comparison (A beats B, A has the smaller spread) needs "
               f"{settings.min_n} finished trials per arm and is judged once, on each arm's seeds 0 to planned n - 1 "
               "(results/paper/claims.yaml; a look between the two is interim, shown but no verdict); it is Welch's t "
               "at the larger of its permutation and t-distribution p, Holm-corrected over every primary comparison "
               f"the settings declare (one not yet judged enters at p = 1), at alpha {settings.alpha:g}: "
               "reproduced where it rejects in the claim's direction, not reproduced where it rejects the other way "
               "or TOST shows the arms equivalent within "
               "the claim's margin (results/paper/claims.yaml), inconclusive otherwise, with the trials 80% power "
               "would need. A threshold row reads a Student t interval of the mean (an order-statistic interval of "
               "the median for convergence points): entirely on the claim's side = reproduced, entirely on the "
               f"other = not reproduced, across = inconclusive. Final return = the mean of the last "
               f"{settings.final_tail} evaluations compared (the single last one shown as a sensitivity reading). "
               "rliable's probability of improvement is description only (Agarwal et al., 2021). A comparison "
               "whose baseline fails its check (the row it requires), or where neither arm solves the task, "
               "is not made.")
    table = Table(f"{entry.ref}. {entry.title}", caption,
                  ["Claim", "Paper", "Suite (test; interval)", "Budget (trials)", "Verdict", "Rule", "Source"],
                  rows, pd.DataFrame(records))
    judged_n = sum(r["suite_value"] is not None for r in records)
    return Output(table=table, trials={"claims with a suite value": judged_n}, empty=judged_n == 0)
