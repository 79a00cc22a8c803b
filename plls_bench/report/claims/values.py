"""Claim measurements that read one number per trial or trained model (representation MSE,
latent-space studies, parameter counts, the filmstrip), and the helpers every claim kind shares:
the budget text and a mean with its Student t interval. The kinds on return curves are in
:mod:`plls_bench.report.claims.claims_table`."""
from __future__ import annotations

import math

import numpy as np

from plls_bench.core.metric_rows import POLICIES
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.matched import NotJudged, require_trials
from plls_bench.report.evidence.protocol import t_interval
from plls_bench.report.evidence.table_formats import NA, fmt
from plls_bench.report.evidence.verdicts import Estimate
from plls_bench.report.tables.efficiency import parameter_counts
from plls_bench.rundirs.run_dir import PARAMS_FILE

NAN2 = (math.nan, math.nan)


def budget_text(runs: Runs, *names: str, n: list[int] | None = None) -> str:
    exps = [runs.experiment(name) for name in names]
    counts = n or [len(e.trials) for e in exps]
    word = "trial" if counts == [1] else "trials"
    return f"{'/'.join(sorted({e.budget or NA for e in exps}))} ({' + '.join(map(str, counts))} {word})"


def policy_of(claim: dict[str, str]) -> str:
    """The test returns a curve claim reads: a ``param`` that is, or ends in ``:``, a policy of
    POLICIES ("final:stochastic": sampled actions); the deterministic policy otherwise (D20)."""
    last = claim["param"].rpartition(":")[2]
    return last if last in POLICIES else "deterministic"


def repr_mse(runs: Runs, claim: dict[str, str], _settings: object = None) -> Estimate:
    """Mean test MSE over distinct trained models (trials sharing an artifact count once).
    ``param`` is ``model`` (z sampled, ``test_mse``) or ``model:field`` (e.g. the decode(mu)
    reading, ``action:test_mse_posterior_mean``)."""
    exp = runs.experiment(claim["experiment"])
    model, _, field = claim["param"].partition(":")
    field = field or "test_mse"
    values: dict[str, float] = {}
    for trial in exp.trials:
        entry = (runs.json(exp, trial, "metrics/repr_test.json") or {}).get(model)
        if isinstance(entry, dict) and isinstance(entry.get(field), (int, float)):
            values.setdefault(str(entry.get("artifact", trial.seed)), float(entry[field]))
    if not values:
        raise NotJudged(f"no {field} of model {model} in {exp.name}")
    # stochastic: each trained model is one draw (trials sharing a model count once)
    require_trials([len(values)], budget_text(runs, exp.name), "trained models")
    return mean_estimate(list(values.values()), "model", budget_text(runs, exp.name))


def study_metric(runs: Runs, claim: dict[str, str], _settings: object = None) -> Estimate:
    """Mean over trials of the number ``param`` of ``metrics/study.json`` (a latent-space study;
    each trial samples its own actions from the same V_a)."""
    exp = runs.experiment(claim["experiment"])
    values = [(runs.json(exp, trial, "metrics/study.json") or {}).get(claim["param"]) for trial in exp.trials]
    values = [float(v) for v in values if isinstance(v, (int, float)) and math.isfinite(v)]
    if not values:
        raise NotJudged(f"no {claim['param']} in {exp.name}'s metrics/study.json")
    require_trials([len(values)], budget_text(runs, exp.name, n=[len(values)]))  # stochastic: actions are sampled
    return mean_estimate(values, "trial", budget_text(runs, exp.name, n=[len(values)]))


def mean_estimate(values: list[float], unit: str, budget: str) -> Estimate:
    """The mean of ``values`` with its 95% Student t interval (valid at any n >= 2 for roughly
    normal values, where a percentile bootstrap at 3 values is their range), shown as
    mean ± std (n units), t-interval."""
    x = np.array(values, dtype=float)
    ci = t_interval(x)
    std = float(x.std(ddof=1)) if len(x) > 1 else 0.0
    text = f"{fmt(float(x.mean()))} ± {fmt(std)} ({len(x)} {unit}{'s' if len(x) > 1 else ''})"
    if not math.isnan(ci[0]):
        text += f", t-interval [{fmt(ci[0])}, {fmt(ci[1])}]"
    return Estimate(float(x.mean()), ci, text, budget)


def param_count(runs: Runs, claim: dict[str, str], _settings: object = None) -> Estimate:
    """Deterministic (the architecture fixes it): one trial suffices, even an unfinished one carried
    as a partial record."""
    params = parameter_counts(runs, runs.experiment(claim["experiment"]))
    if params is None:
        raise NotJudged(f"no {PARAMS_FILE} in {claim['experiment']}")
    value = float(getattr(params, claim["param"]))
    budget = params.source_text or budget_text(runs, claim["experiment"])
    return Estimate(value, NAN2, fmt(value), budget)


def steps_to_goal(runs: Runs, claim: dict[str, str], _settings: object = None) -> Estimate:
    """Fig. 11's filmstrip: the paper drives one car with one learned policy from a fixed s0. The
    suite films the first trial's policy, acting deterministically from that s0, so one trial is
    the measurement (it stays one value, with no CI)."""
    exp = runs.experiment(claim["experiment"])
    trial = runs.first_with(exp, "filmstrip/filmstrip.json")
    steps = (runs.json(exp, trial, "filmstrip/filmstrip.json") or {}).get("steps_to_goal") if trial else None
    if trial is None:
        raise NotJudged(f"no filmstrip in {exp.name}")
    value = math.inf if not isinstance(steps, (int, float)) else float(steps)
    text = "goal not reached" if math.isinf(value) else f"{fmt(value)} steps (seed {trial.seed})"
    return Estimate(value, NAN2, text, budget_text(runs, exp.name, n=[1]))
