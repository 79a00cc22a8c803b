"""Acting on the mean or sampling actions: per PPO arm, the final return of the same trials' test
episodes read both ways, and whether the two differ (docs/decisions.md#d20: the paper does not say
which its test episodes did). Under SB3's Gaussian, plain PPO on CarRacing keeps an action SD near 1
and its two readings reverse Fig. 18's ranking; this table shows, per exploration setting, where the
readings agree. A declared sweep's other values (``conf/sweep/<name>.yaml``) get a row each beside the
preset's own: N_e changes how far V_a's latent mean is from the actions the policy trained on."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from plls_bench.pipeline.sweeps import load_sweep
from plls_bench.report.evidence.claim_settings import ClaimSettings, load_settings
from plls_bench.report.evidence.entry_types import Entry, Options, Output
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.protocol import one_sample_p, t_interval, tail_mean
from plls_bench.report.evidence.returns import DEFAULT_X_AXIS, Curves, load_curves
from plls_bench.report.evidence.sweep_arms import sweep_experiments
from plls_bench.report.evidence.table_formats import NA, Table, fmt
from plls_bench.report.evidence.trials import Experiment

COLUMNS = ["Arm", "Exploration", "Budget", "Trials", "Final, acting on the mean", "Final, sampled actions",
           "Sampled - mean [95% t-interval]", "Paired test", "Readings"]


def caption(settings: ClaimSettings) -> str:
    return (
        "Each PPO arm's finished trials, their test episodes read two ways at every evaluation: acting on the "
        "policy's mean action, and sampling actions from it (docs/decisions.md#d20; the paper does not say "
        f"which). Final = mean return over the last {settings.final_tail} evaluations (results/paper/claims.yaml, "
        "final_tail, as in the claims rows), mean ± sample SD over trials. The two readings of one trial are "
        "paired: the difference per trial is tested by a two-sided one-sample t-test against 0 at alpha = "
        f"{settings.alpha:g}, each arm on its own (a description of the evaluation mode, not a claim of the "
        f"paper, so no Holm family), and only from {settings.min_n} trials. 'No difference found' is not "
        "a proof of equality. A declared sweep's values other than the preset's own (conf/sweep/<name>.yaml) "
        "follow as rows of their own, each its run-dir variant.")


def paired_finals(det: Curves, sampled: Curves, tail: int) -> tuple[np.ndarray, np.ndarray]:
    """Per finished trial seen both ways, the final of each reading: two ``(n,)`` arrays in seed order."""
    def finals(curves: Curves) -> dict[int, float]:
        done = curves.finished_seeds()
        out = {}
        for seed, values, finished in zip(curves.seeds, curves.values, done):
            seen = values[~np.isnan(values)]
            if finished and len(seen):
                out[seed] = float(tail_mean(seen, min(tail, len(seen))))
        return out
    a, b = finals(det), finals(sampled)
    seeds = sorted(set(a) & set(b))
    return np.array([a[s] for s in seeds]), np.array([b[s] for s in seeds])


def readings(diff: np.ndarray, settings: ClaimSettings) -> tuple[str, str, float]:
    """(test text, outcome, two-sided p) for the per-trial differences ``diff`` ``(n,)``."""
    n = len(diff)
    if n < settings.min_n:
        return f"not tested: needs {settings.min_n} trials, has {n}", "not tested", math.nan
    p = min(1.0, 2 * min(one_sample_p(diff, 0.0, "greater"), one_sample_p(diff, 0.0, "less")))
    sd = diff.std(ddof=1)
    t = diff.mean() / (sd / math.sqrt(n)) if sd > 0 else math.copysign(math.inf, diff.mean() or 1.0)
    outcome = "no difference found"
    if p <= settings.alpha:
        outcome = "sampled higher" if diff.mean() > 0 else "acting on the mean higher"
    return f"paired t = {t:.2f}, p = {fmt(p)}", outcome, p


def _spread(values: np.ndarray) -> str:
    if not len(values):
        return NA
    return fmt(values.mean()) + (f" ± {fmt(values.std(ddof=1))}" if len(values) > 1 else "")


def _arm(runs: Runs, exp: Experiment, name: str, settings: ClaimSettings) -> tuple[list[str], dict, int]:
    """One row: ``exp``'s finished trials read both ways; ``name`` is the row's first cell."""
    exploration = NA if not exp.trials else "gSDE" if exp.cfg("algo.ppo.use_sde") else "Gaussian"
    det, sampled = (load_curves(runs, exp, name, DEFAULT_X_AXIS, policy=p) for p in ("deterministic", "stochastic"))
    mean_final, sampled_final = paired_finals(det, sampled, settings.final_tail)
    diff = sampled_final - mean_final
    test, outcome, p = readings(diff, settings) if len(diff) else ("no finished trials", "not run", math.nan)
    low, high = t_interval(diff) if len(diff) > 1 else (math.nan, math.nan)
    interval = NA if not len(diff) else fmt(diff.mean()) + (f" [{fmt(low)}, {fmt(high)}]" if len(diff) > 1 else "")
    cells = [name, exploration, exp.budget or NA, str(len(diff)),
             _spread(mean_final), _spread(sampled_final), interval, test, outcome]
    record = {"experiment": exp.name, "variant": exp.variant, "exploration": exploration, "budget": exp.budget,
              "trials": len(diff), "final_mean_action": float(mean_final.mean()) if len(diff) else math.nan,
              "final_sampled": float(sampled_final.mean()) if len(diff) else math.nan,
              "difference": float(diff.mean()) if len(diff) else math.nan, "p": p, "readings": outcome}
    return cells, record, len(diff)


def _arms(entry: Entry, runs: Runs, sweeps: tuple[str, ...]) -> list[tuple[Experiment, str, str]]:
    """``(runs, row name, trials key)`` per source of ``entry``, then per other value of each sweep in
    ``sweeps``; the key names the preset because labels repeat across tasks."""
    arms = [(runs.experiment(s.experiment), f"{s.label} (`{s.experiment}`)", f"{s.label} ({s.experiment})")
            for s in entry.sources]
    labels = {s.experiment: s.label for s in entry.sources}
    for spec in map(load_sweep, sweeps):
        for value, exp in sweep_experiments(runs, spec, spec.others):
            label = f"{labels.get(spec.preset, spec.preset)}, {spec.override(value)}"
            arms.append((exp, f"{label} (`{spec.preset}`, sweep `{spec.name}`)",
                         f"{label} ({spec.preset}, sweep {spec.name})"))
    return arms


def evaluation_modes(runs: Runs, entry: Entry, opts: Options, *, sweeps: tuple[str, ...] = ()) -> Output:
    """One row per arm of ``entry.sources``, then one per other value of each declared sweep."""
    settings = load_settings(opts.paper_dir, None)  # the protocol block; the claims table checks the names
    rows, records, trials = [], [], {}
    for exp, name, key in _arms(entry, runs, sweeps):
        cells, record, n = _arm(runs, exp, name, settings)
        rows.append(cells)
        records.append(record)
        trials[key] = n
    table = Table(f"{entry.ref}. {entry.title}", caption(settings), COLUMNS, rows, pd.DataFrame(records))
    return Output(table=table, trials=trials, empty=not any(trials.values()))
