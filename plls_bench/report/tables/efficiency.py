"""Tables 1 and 2 (PPO hyper-parameters, rendered from the configs the runs used) and Table 3
(parameter counts and samples to convergence, measured from the runs), each beside the paper's
numbers from ``results/paper/table{1,2,3}.csv``."""
from __future__ import annotations

import math
from dataclasses import dataclass

import pandas as pd

from plls_bench.core.metric_rows import parallel_envs
from plls_bench.report.evidence.entry_types import Entry, Options, Output, Source
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.returns import Convergence, convergence, load_curves
from plls_bench.report.evidence.stats import CONVERGENCE_TOLERANCE, CONVERGENCE_WINDOW
from plls_bench.report.evidence.table_formats import NA, Table, fmt, plural, read_paper
from plls_bench.report.evidence.trials import Experiment, Trial
from plls_bench.rundirs.run_dir import PARAMS_FILE

CONVERGENCE_RULE = (
    f"Convergence: the mean return over trials at each evaluation, smoothed by a trailing mean over "
    f"{CONVERGENCE_WINDOW} evaluations; the first evaluation after which the smoothed value stays within "
    f"{CONVERGENCE_TOLERANCE:.0%} of its final value, with at least {CONVERGENCE_WINDOW} evaluations in that "
    f"stable tail (otherwise: not converged within the budget). Trials that stop before the last "
    f"evaluation are left out. Brackets: 95% bootstrap CI over trials (percentile, fixed seed).")


def _paper_number(text: str) -> float | None:
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


def _paper_text(text: str | None) -> str:
    """A paper cell: formatted like the suite's numbers when it is one, else as written."""
    number = _paper_number(text)
    return fmt(number) if number is not None else (text or NA)


def _same(a: object, b: float | None) -> bool:
    return isinstance(a, (int, float)) and b is not None and math.isclose(float(a), b, rel_tol=1e-9)


def hyperparameters(runs: Runs, entry: Entry, opts: Options, *, paper: str) -> Output:
    """One row per paper hyper-parameter: the paper's value, then each source's value read
    from its runs' ``config.json`` (a ``*`` marks a value that differs from the paper's)."""
    rows_in = read_paper(opts.paper_dir, paper)
    exps = [runs.experiment(s.experiment) for s in entry.sources]
    rows, records, differs = [], [], False
    for row in rows_in:
        cells = [row["hyperparameter"], row["key"], row["paper_value"]]
        for i, exp in enumerate(exps):
            value = exp.cfg(row["key"])
            want = _paper_number(row["paper_baseline"] if i > 0 and row["paper_baseline"] else row["paper_value"])
            mark = "" if value is None or _same(value, want) else "*"
            differs |= bool(mark)
            cells.append(NA if value is None else fmt(value) + mark)
            records.append({"hyperparameter": row["hyperparameter"], "key": row["key"],
                            "paper": row["paper_value"], "method": entry.sources[i].label,
                            "experiment": exp.name, "suite": value, "budget": exp.budget, "source": row["source"]})
        rows.append(cells)
    budgets = ", ".join(f"{s.label}: {e.budget_text} ({plural(len(e.trials), 'run')})"
                        for s, e in zip(entry.sources, exps))
    notes = ["* differs from the paper. At smoke budget a per-algorithm file shrinks the vector env "
             "(conf/algo/per_budget/); plain PPO's learning rate on MountainCar is 3e-4 (Sec. 5.1)."]
    notes = notes if differs else []
    baseline_note = [f"Paper's plain PPO differs: {r['hyperparameter']} = {r['paper_baseline']}"
                     for r in rows_in if r["paper_baseline"]]
    table = Table(f"{entry.ref}. {entry.title}",
                  f"Values rendered from the config.json of the runs ({budgets}); paper values from "
                  f"results/paper/{paper}.csv.",
                  ["Hyperparameter", "Config key", "Paper", *[f"{s.label} (suite)" for s in entry.sources]],
                  rows, pd.DataFrame(records), notes + baseline_note)
    return Output(table=table, trials={s.label: len(e.trials) for s, e in zip(entry.sources, exps)},
                  empty=not any(e.trials for e in exps))


# --------------------------------------------------------------------------- Table 3
@dataclass(frozen=True)
class ParameterCounts:
    """``metrics/params.json``'s counts and the trial they were read from."""

    total: int
    trainable: int
    trial: Trial

    @property
    def source_text(self) -> str:
        """Where the counts come from, for a trial that is not one of the experiment's own."""
        if self.trial.source != "partial":
            return ""
        return (f"seed {self.trial.seed}'s unfinished {self.trial.cfg('budget.name', NA)}-budget trial "
                f"(partial record)")


def parameter_counts(runs: Runs, exp: Experiment) -> ParameterCounts | None:
    """``metrics/params.json`` of the lowest seed that has it; a trial with other counts is a gap.
    With no trial, those of an unfinished trial carried as a partial record: the architecture fixes
    them, so a run knows them in full from its start."""
    found = _counts(runs, exp, exp.trials)
    if found is None and not exp.trials:
        found = _counts(runs, exp, runs.partial_trials(exp.name, exp.variant), gaps=False)
    if found is None and exp.trials:
        runs.gap(exp, None, f"no trial has {PARAMS_FILE}")
    return found


def _counts(runs: Runs, exp: Experiment, trials: list[Trial], gaps: bool = True) -> ParameterCounts | None:
    found = None
    for trial in trials:
        if not (trial.path / PARAMS_FILE).is_file():
            continue
        params = runs.json(exp, trial, PARAMS_FILE)
        if params is None or not all(isinstance(params.get(k), int) for k in ("total", "trainable")):
            if gaps:
                runs.gap(exp, trial, f"{PARAMS_FILE} lacks integer total/trainable")
        elif found is None:
            found = ParameterCounts(params["total"], params["trainable"], trial)
        elif (params["total"], params["trainable"]) != (found.total, found.trainable) and gaps:
            runs.gap(exp, trial, f"{PARAMS_FILE} counts {params['total']}/{params['trainable']} differ "
                                 f"from the first trial's {found.total}/{found.trainable}")
    return found


def fmt_convergence(result: Convergence | None) -> str:
    """``12 [10, 14]``; ``not converged by 22`` (every resample agrees); ``12 [10, not converged]``."""
    if result is None:
        return NA

    def one(x: float) -> str:
        return "not converged" if math.isinf(x) else fmt(x)

    point = f"not converged by {fmt(result.last_x)}" if math.isinf(result.x) else fmt(result.x)
    low, high = result.ci
    if math.isnan(low) or (math.isinf(low) and math.isinf(result.x)) or low == high == result.x:
        return point
    return f"{point} [{one(low)}, {one(high)}]"


def _scaled(result: Convergence | None, divisor: float) -> Convergence | None:
    if result is None:
        return None
    return Convergence(result.x / divisor, (result.ci[0] / divisor, result.ci[1] / divisor), result.n,
                       result.last_x / divisor)


def _efficiency_row(runs: Runs, source: Source, ref: dict[str, str]) -> tuple[list[str], dict]:
    """Table 3's cells and CSV record for one method."""
    exp = runs.experiment(source.experiment)
    params = parameter_counts(runs, exp)
    conv = {axis: convergence(load_curves(runs, exp, source.label, axis))
            for axis in ("iteration", "env_steps", "env_steps_per_env")}
    conv["sampled_frequency"] = _scaled(conv["env_steps_per_env"], float(parallel_envs(exp.cfg)))
    n = max((c.n for c in conv.values() if c), default=0)
    total, trainable = (params.total, params.trainable) if params else (None, None)
    cells = [source.label, fmt(total), fmt(_paper_number(ref.get("total_parameters"))),
             fmt(trainable), fmt(_paper_number(ref.get("trainable_parameters"))),
             fmt_convergence(conv["iteration"]), fmt_convergence(conv["env_steps"]),
             fmt_convergence(conv["env_steps_per_env"]), _paper_text(ref.get("iterations_to_convergence")),
             fmt_convergence(conv["sampled_frequency"]), fmt(_paper_number(ref.get("sampled_frequency"))),
             str(n), exp.budget or (f"parameters: {params.source_text}" if params else NA)]
    record = {"model": source.label, "experiment": exp.name, "budget": exp.budget, "trials": n,
              "total_parameters": total, "trainable_parameters": trainable,
              "parameters_from": params.source_text if params else None,
              **{f"paper_{k}": ref.get(k) for k in ("total_parameters", "trainable_parameters",
                                                     "iterations_to_convergence", "sampled_frequency")}}
    for axis, result in conv.items():
        record.update({f"converged_{axis}": result.x if result else None,
                       f"converged_{axis}_ci_low": result.ci[0] if result else None,
                       f"converged_{axis}_ci_high": result.ci[1] if result else None})
    return cells, record


TABLE3_CAPTION = (
    "Total parameters: every module the method needs at run time (frozen V_s and V_a included); trainable: "
    f"what PPO updates ({PARAMS_FILE}). The paper's CarRacing 'iteration' is read as one step of the "
    "vector env, i.e. environment steps per parallel env (so its 120,000 iterations are the paper budget's "
    "1,920,000 env steps over 16 envs); Sampled_Frequency = those iterations to convergence / parallel envs, "
    "as the paper's 60,000 / 16 = 3,750. ")


def learning_efficiency(runs: Runs, entry: Entry, opts: Options) -> Output:
    """Table 3: parameters (``params.json``) and PPO iterations / env steps / env steps per env
    (the paper's iterations) / Sampled_Frequency to convergence (``eval.jsonl``) per method,
    beside the paper's row."""
    paper = {row["experiment"]: row for row in read_paper(opts.paper_dir, "table3")}
    rows, records, trials = [], [], {}
    for source in entry.sources:
        cells, record = _efficiency_row(runs, source, paper.get(source.experiment, {}))
        rows.append(cells)
        records.append(record)
        trials[source.label] = record["trials"]
    columns = ["Model", "Total (suite)", "Total (paper)", "Trainable (suite)", "Trainable (paper)",
               "PPO iterations to convergence", "Env steps to convergence",
               "Env steps per env to convergence (suite)", "Iterations to convergence (paper)",
               "Sampled_Frequency (suite)", "Sampled_Frequency (paper)", "Trials", "Budget"]
    table = Table(f"{entry.ref}. {entry.title}", TABLE3_CAPTION + CONVERGENCE_RULE, columns, rows,
                  pd.DataFrame(records))
    return Output(table=table, trials=trials,
                  empty=not any(runs.experiment(s.experiment).trials for s in entry.sources))
