"""The power table (``results/tables/power.{md,csv}``): for every comparison claim, each arm's
observed final score and spread, the trials per arm that 80% power would need at the observed
effect (Welch's test at alpha, and at alpha / m, the first step of Holm's correction over the m
primary comparisons), the paper's own trial count, the planned n of ``claims.yaml``, and what a
trial costs by the dry run's rates (:mod:`plls_bench.report.claims.costs`)."""
from __future__ import annotations

import numpy as np
import pandas as pd

from plls_bench.report.claims.claims_table import KINDS, read_claims
from plls_bench.report.claims.costs import more_trials
from plls_bench.report.evidence.claim_settings import ClaimSettings, load_settings
from plls_bench.report.evidence.entry_types import Entry, Options, Output
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.looks import planned_seeds
from plls_bench.report.evidence.matched import NotJudged
from plls_bench.report.evidence.protocol import Comparison, planned_n
from plls_bench.report.evidence.table_formats import NA, Table, fmt

CAPTION = (
    "Trials per arm that 80% power needs at the observed effect, for every comparison claim "
    "(docs/verdicts.md). Score: the row's per-trial score (final = mean of the last evaluations "
    "compared; for a spread claim, each trial's absolute deviation from its arm's median). n for 80%: "
    "the fewest trials per arm at which Welch's two-sided test at alpha reaches 80% power if the observed "
    "means and SDs were the truth (noncentral t; the protocol decides on the larger of Welch's permutation and "
    "t-distribution p, whose power stays within about one point of it: tests/test_verdict_calibration.py); "
    "at alpha / m: the same at the "
    "first step of Holm's correction over the m primary comparisons (a bound: later steps need less). "
    "Observed effects from 3 trials are themselves noisy, so these are orders of magnitude. Planned n: the "
    "trials per arm the row is judged at, once (claims.yaml's planned_n; a plan below the n at which the "
    "test can reject is refused: a primary row Holm-corrected over m needs 2 / C(2n, n) <= alpha / m; "
    "docs/verdicts.md, One look per row). Cost per trial: "
    "the dry run's estimate of one more trial of each arm (python -m plls_bench.reproduce --dry-run), "
    "from the rates in bench/throughput.json measured on the reference CPU.")


def _hours(seconds: float | None) -> str:
    return NA if seconds is None else f"{seconds / 3600:.2f} h"


def _row(runs: Runs, claim: dict[str, str], settings: ClaimSettings, family: int) -> tuple[list[str], dict]:
    record = {"claim": claim["claim"], "arms": f"{claim['experiment']} vs {claim['baseline'] or 'other values'}",
              "paper_n": settings.comparisons[claim["claim"]].paper_n,
              "planned_n": settings.planned(claim["claim"])}
    try:
        comp = KINDS[claim["kind"]](runs, claim, settings).comparison
    except NotJudged as err:
        comp, record["note"] = None, str(err)
    if comp is not None:
        need = planned_n(comp.effect, comp.sd_a, comp.sd_b, power=settings.power, alpha=settings.alpha,
                         min_n=settings.min_n) if comp.n_a > 1 and comp.n_b > 1 else None
        holm_first = planned_n(comp.effect, comp.sd_a, comp.sd_b, power=settings.power,
                               alpha=settings.alpha / max(family, 1), min_n=settings.min_n) if need else None
        record.update(n_a=comp.n_a, n_b=comp.n_b, mean_a=comp.mean_a, sd_a=comp.sd_a, mean_b=comp.mean_b,
                      sd_b=comp.sd_b, effect=comp.effect, n_power=need, n_power_holm=holm_first)
    # a row with no runs yet is costed at the least budget it is judged at, so its whole plan is priced
    budget = runs.experiment(claim["experiment"]).budget or claim["min_budget"] or None
    counts = _counts(runs, claim, comp, record["planned_n"])
    more = more_trials(claim["experiment"], claim["baseline"], budget, counts, record["planned_n"])
    record["cost_per_trial_s"] = None if None in more.per_trial_s else sum(more.per_trial_s)
    record["cost_to_planned_s"] = more.seconds  # each arm from its own count (3 + 5 needs 4 + 2 to 7)
    spread = min(record.get("n_a", 0), record.get("n_b", 0)) > 1  # an SD per arm to plan with
    cells = [claim["claim"], record["arms"],
             f"{record['n_a']} + {record['n_b']}" if "n_a" in record else NA,
             f"{fmt(record['mean_a'])} ± {fmt(record['sd_a'])}" if "n_a" in record else NA,
             f"{fmt(record['mean_b'])} ± {fmt(record['sd_b'])}" if "n_a" in record else NA,
             fmt(record.get("effect")), _n_text(record.get("n_power"), spread),
             _n_text(record.get("n_power_holm"), spread), fmt(record["paper_n"]), str(record["planned_n"]),
             _hours(record["cost_per_trial_s"]), _hours(record["cost_to_planned_s"])]
    return cells, record


def _counts(runs: Runs, claim: dict[str, str], comp: Comparison | None, planned: int | None) -> tuple[int, int]:
    """Each arm's trials toward the plan: the comparison's, or for a row not judged yet (an arm with
    no runs) each arm's finished trials of the seeds the plan names (0 to ``planned`` - 1), so 4 + 0
    of a planned 6 is priced as 2 + 6 more, and a seed past the plan does not stand in for one in it."""
    if comp is not None:
        return comp.n_a, comp.n_b

    def in_plan(name: str) -> int:
        seeds = np.array([t.seed for t in runs.experiment(name).trials], dtype=int)
        return int(planned_seeds(np.ones(len(seeds), dtype=bool), seeds, planned).sum())

    # a sweep's other arm is its other values (variants), not the preset's own runs
    return in_plan(claim["experiment"]), in_plan(claim["baseline"]) if claim["baseline"] else 0


def _n_text(n: int | None, measured: bool) -> str:
    if not measured:
        return NA
    return "> 1000 or no effect" if n is None else str(n)


def power_table(runs: Runs, entry: Entry, opts: Options) -> Output:
    """One row per comparison claim of ``claims.yaml``."""
    claims = read_claims(opts.paper_dir)
    settings = load_settings(opts.paper_dir, [c["claim"] for c in claims])
    family = settings.family_size
    rows, records = [], []
    for claim in claims:
        if claim["claim"] in settings.comparisons:
            cells, record = _row(runs, claim, settings, family)
            rows.append(cells)
            records.append(record)
    columns = ["Claim", "Arms (A vs B)", "Trials", "A: score ± SD", "B: score ± SD", "Effect (A - B)",
               "n for 80% (alpha)", f"n for 80% (alpha / {family})", "Paper's n", "Planned n",
               "Cost per trial (A + B)", "Cost to planned n (both arms)"]
    measured = sum("n_a" in r for r in records)
    table = Table(f"{entry.ref}. {entry.title}", CAPTION, columns, rows, pd.DataFrame(records))
    return Output(table=table, trials={"comparison claims with scores": measured}, empty=measured == 0)

