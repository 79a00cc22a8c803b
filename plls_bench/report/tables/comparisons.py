"""Statistics the paper does not give, for every return comparison (Figs 10, 18, 20, 21): per
method the final return's mean and IQM and the mean return over the curve, each with a 95%
stratified-bootstrap CI, and the probability that PL-LS improves on each baseline."""
from __future__ import annotations

import numpy as np
import pandas as pd

from plls_bench.report.evidence.claim_settings import load_settings
from plls_bench.report.evidence.entry_types import Entry, Options, Output
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.matched import NotJudged, matched
from plls_bench.report.evidence.protocol import tail_mean
from plls_bench.report.evidence.returns import DEFAULT_X_AXIS, Curves, Scores, load_curves
from plls_bench.report.evidence.stats import SCORE_RESAMPLES, SEED, probability_of_improvement, summarise
from plls_bench.report.evidence.table_formats import NA, Table, fmt, fmt_ci

CAPTION = (
    "Every method of a comparison is measured where all of them were: on the evaluations that every "
    "finished trial (status done) of every method reaches, up to the x in the last column. Per trial: "
    "final = mean return over the last {tail} of those evaluations (results/paper/claims.yaml, final_tail, "
    "as in the claims rows), curve = mean return over them (area under the curve / its length); a method run "
    "longer is not credited with its later evaluations. Mean and IQM (mean of "
    "the middle 50% of trials) as rliable.metrics computes them; P(PL-LS > method) = P(X > Y) + P(X = Y)/2 "
    f"over pairs of trials (rliable's probability of improvement). 95% CIs: percentile bootstrap, "
    f"{SCORE_RESAMPLES:,} resamples, random state {SEED}, trials resampled within each method "
    "(stratified), none for a single trial.")


FEW_TRIALS = 10  # below this many trials per method, these statistics describe and cannot test
FEW_NOTE = ("Description only: some methods have {n} trials. At 3 trials a 95% percentile-bootstrap interval of a "
            "mean is the trials' range (each trial is all of a resample with probability 1/27 > 2.5%), the IQM equals "
            "the mean, and P(PL-LS > method) takes one of 10 values (k/9). Verdicts are decided by the protocol of "
            "docs/verdicts.md, not by these intervals.")


def _row(comparison: Entry, label: str, budget: str | None, own: Scores,
         method: Scores | None) -> tuple[list[str], dict]:
    record = {"figure": comparison.id, "method": label, "budget": budget, "trials": len(own.final),
              "compared_at": own.last_x}
    cells = [comparison.ref, label, budget or NA, str(len(own.final))]
    for name, values in (("final", own.final), ("curve", own.auc)):
        if len(values):
            s = summarise(values)
            record.update({f"{name}_mean": s.mean, f"{name}_mean_ci_low": s.mean_ci[0],
                           f"{name}_mean_ci_high": s.mean_ci[1], f"{name}_iqm": s.iqm,
                           f"{name}_iqm_ci_low": s.iqm_ci[0], f"{name}_iqm_ci_high": s.iqm_ci[1]})
            cells += [fmt_ci(s.mean, s.mean_ci)] + ([fmt_ci(s.iqm, s.iqm_ci)] if name == "final" else [])
        else:
            cells += [NA] + ([NA] if name == "final" else [])
    for name in ("final", "auc"):
        x, y = (getattr(method, name), getattr(own, name)) if method else ((), ())
        if method is not None and len(x) and len(y):
            p, ci = probability_of_improvement(x, y)
            record.update({f"p_improvement_{name}": p, f"p_improvement_{name}_ci_low": ci[0],
                           f"p_improvement_{name}_ci_high": ci[1]})
            cells.append(fmt_ci(p, ci, 3))
        else:
            cells.append(NA)
    cells.append(fmt(own.last_x))
    return cells, record


def matched_scores(runs: Runs, methods: list[Curves], tail: int) -> list[Scores]:
    """Each method's finished trials scored on the evaluations all of them reach, final over the last
    ``tail`` of them (no scores for a method without finished trials, or for all when they share no
    evaluation)."""
    present = [i for i, c in enumerate(methods) if c.finished_seeds().any()]
    try:
        pair = matched(*[methods[i] for i in present], runs=runs) if present else None
    except NotJudged:
        pair = None
    out = []
    for i, curves in enumerate(methods):
        seeds = tuple(s for s, done in zip(curves.seeds, curves.finished_seeds()) if done)
        if pair is None or i not in present:
            out.append(Scores(curves.label, seeds, np.zeros(0), np.zeros(0), np.nan))
            continue
        values = pair.values[present.index(i)]
        final = tail_mean(values, min(tail, values.shape[1]))
        out.append(Scores(curves.label, seeds, final, values.mean(axis=1), float(pair.grid[-1])))
    return out


def return_statistics(runs: Runs, entry: Entry, opts: Options, *, comparisons: tuple[Entry, ...]) -> Output:
    """One row per (comparison, method); the first source of each comparison is PL-LS."""
    rows, records, trials = [], [], {}
    tail = load_settings(opts.paper_dir, None).final_tail  # the protocol block; the claims table checks the names
    for comparison in comparisons:
        all_scores = matched_scores(runs, [load_curves(runs, runs.experiment(s.experiment), s.label, DEFAULT_X_AXIS)
                                     for s in comparison.sources], tail)
        method = all_scores[0]
        for source, own in zip(comparison.sources, all_scores):
            budget = runs.experiment(source.experiment).budget
            cells, record = _row(comparison, source.label, budget, own, None if own is method else method)
            rows.append(cells)
            records.append(record)
            trials[f"{comparison.ref} {source.label}"] = len(own.final)
    columns = ["Figure", "Method", "Budget", "Trials", "Final return, mean [95% CI]", "Final return, IQM [95% CI]",
               "Mean return over the curve [95% CI]", "P(PL-LS > method), final [95% CI]",
               "P(PL-LS > method), curve [95% CI]", "Compared at (iteration)"]
    table = Table(f"{entry.ref}. {entry.title}", CAPTION.format(tail=tail), columns, rows, pd.DataFrame(records))
    fewest = min((n for n in trials.values() if n), default=0)
    if 0 < fewest < FEW_TRIALS:
        table.notes.append(FEW_NOTE.format(n=fewest))
    return Output(table=table, trials=trials, empty=not any(trials.values()))
