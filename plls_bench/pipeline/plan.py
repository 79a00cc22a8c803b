"""What a profile runs and what it costs, without running anything.

Every preset of a profile is composed exactly as ``python -m plls_bench`` will compose it, so the
run dirs and config hashes here are the ones the runner checks: a trial counted as done here is
one the runner will skip, or one a committed record holds (``plls_bench.records``), which
``reproduce`` does not launch. Cost estimates use throughput measured on a reference machine
(:mod:`plls_bench.pipeline.rates`); shared artifacts (datasets, representations) are costed once, by the
first preset that needs them.
"""
from __future__ import annotations

import dataclasses
import fnmatch
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from plls_bench.config import Config, ConfigError
from plls_bench.core.hashing import stable_hash
from plls_bench.pipeline.overrides import inert_overrides
from plls_bench.pipeline.rates import load_rates, rate_keys
from plls_bench.pipeline.runner_registry import runner_spec
from plls_bench.pipeline.sweeps import Sweep
from plls_bench.repr.keys import repr_key
from plls_bench.rundirs.artifacts import is_built
from plls_bench.rundirs.composition import CONF_DIR, compose
from plls_bench.rundirs.record_layout import (
    PENDING_DIR,
    is_recorded,
    partial_iteration,
    partial_record,
    recorded_artifact,
    records_dir_for,
)
from plls_bench.rundirs.record_pending import recorded_attempt
from plls_bench.rundirs.run_dir import Run, config_hash, run_dir_path, variant_name, variant_overrides
from plls_bench.train.schedule import Schedule


@dataclass(frozen=True)
class Trial:
    seed: int
    run_dir: Path
    done: bool                                    # status.json says done for this exact config
    cfg: Config = field(repr=False, compare=False)  # the config the runner will get
    recorded: bool = False                        # a committed record says done for this config
    resumes_at: int = 0                           # iteration of the checkpoint it resumes from
    resumes_from: str = ""                        # "run dir" or "partial record" ("": starts afresh)
    iterations: int = 0                           # iterations of the whole run (learners; else 0)
    checkpoints: int = 0                          # checkpoints still to come (time-limited learners; else 0)
    lost_at: int = 0                              # iteration an uncarried earlier attempt reached (its pending record)

    @property
    def remaining(self) -> float:
        """Fraction of its policy training still to run (1 for a fresh trial or a non-learner)."""
        return 1.0 - self.resumes_at / self.iterations if self.iterations else 1.0


@dataclass
class PresetPlan:
    experiment: str
    env: str
    runner: str
    trials: list[Trial]
    env_steps_per_trial: int               # policy-learning env steps (0 for non-RL presets)
    trial_seconds: dict[int, float] = field(default_factory=dict)  # seed -> estimated compute of a pending trial
    # seed -> estimated compute until a pending trial can first stop: a time-limited learner's first
    # checkpoint (its artifacts and one checkpoint interval of training), any other trial's end (it
    # runs to its end): the least time left it may start with (pipeline/launch.py)
    first_stop_seconds: dict[int, float] = field(default_factory=dict)
    missing_rates: list[str] = field(default_factory=list)
    overrides: tuple[str, ...] = ()        # a sweep value's command-line override (conf/sweep/)
    count_records: bool = True             # a recorded trial is done (reproduce --rerun-recorded: not)
    inert: list[str] = field(default_factory=list)  # overrides of keys the preset never reads (overrides.py)

    @property
    def label(self) -> str:
        return " ".join((self.experiment, *variant_overrides(self.overrides)))

    @property
    def seconds(self) -> float | None:
        """Estimated compute of the pending trials; None: a rate was never measured."""
        return None if self.missing_rates else sum(self.trial_seconds.values())

    @property
    def pending(self) -> list[Trial]:
        return [t for t in self.trials if not (t.done or (t.recorded and self.count_records))]

    @property
    def recorded(self) -> int:
        """Trials a committed record holds done (with this config)."""
        return sum(t.recorded for t in self.trials)


def list_presets() -> list[str]:
    return sorted(p.stem for p in (CONF_DIR / "experiment").glob("*.yaml"))


def select_presets(presets: list[str], patterns: list[str]) -> list[str]:
    """The presets named by ``patterns``: names or shell-style globs (``mountaincar_*``), in the
    order given; a pattern that matches nothing is an error naming it."""
    chosen: list[str] = []
    for pattern in patterns:
        matched = fnmatch.filter(presets, pattern)
        if not matched:
            raise ConfigError(f"--only: unknown preset(s) {pattern}; known: {', '.join(presets)}")
        chosen += [name for name in matched if name not in chosen]
    return chosen


def preset_config(experiment: str, profile: str, runs_dir: str, overrides: tuple[str, ...] = ()) -> Config:
    return compose([f"+experiment={experiment}", f"budget={profile}", f"runs_dir={runs_dir}", *overrides])


def plan_profile(profile: str, runs_dir: str, only: list[str] | None = None,
                 rates: dict[str, float] | None = None, count_records: bool = True,
                 overrides: tuple[str, ...] = (), variants: list[tuple[str, ...]] | None = None) -> list[PresetPlan]:
    """The presets of ``profile`` (all, or ``only``) in dependency order, with their trials; a
    trial done in the committed records beside ``runs_dir`` counts as done unless not ``count_records``.
    ``overrides`` (e.g. ``precision=bf16``) apply to every preset, as on its command line; each of
    ``variants`` (``reproduce --override``) adds a plan per preset beside its own runs."""
    presets = list_presets()
    chosen = select_presets(presets, only) if only else presets
    plans = []
    for name in chosen:
        plans.append(_plan_preset(name, profile, runs_dir, count_records, overrides))
        plans += [_plan_variant(name, profile, runs_dir, count_records, (*v, *overrides)) for v in variants or ()]
    return _costed(plans, rates)


def _plan_variant(experiment: str, profile: str, runs_dir: str, count_records: bool,
                  overrides: tuple[str, ...]) -> PresetPlan:
    """A ``reproduce --override`` variant of a preset; a setting it cannot compose names the override."""
    try:
        plan = _plan_preset(experiment, profile, runs_dir, count_records, overrides)
    except ConfigError as err:
        raise ConfigError(f"--override {' '.join(overrides)} on {experiment}: {err}") from err
    plan.inert = inert_overrides(plan.trials[0].cfg, overrides) if plan.trials else []
    return plan


def plan_sweep(sweep: Sweep, profile: str, runs_dir: str, rates: dict[str, float] | None = None,
               count_records: bool = True, overrides: tuple[str, ...] = ()) -> list[PresetPlan]:
    """A sweep (``conf/sweep/``): its preset's own runs (the arm of its own value), then one plan
    per other value with that value's override; each value's V_a (or other artifact) is costed once."""
    plans = [_plan_preset(sweep.preset, profile, runs_dir, count_records, overrides)]
    plans += [_plan_preset(sweep.preset, profile, runs_dir, count_records,
                           (sweep.override(v), *sweep.plan_overrides, *overrides))
              for v in sweep.others]
    return _costed(plans, rates)


def _costed(plans: list[PresetPlan], rates: dict[str, float] | None) -> list[PresetPlan]:
    rates = load_rates() if rates is None else rates
    plans.sort(key=lambda p: (runner_spec(p.runner).order, p.experiment))  # artifacts before their consumers
    costed: set[str] = set()
    for plan in plans:
        plan.trial_seconds, plan.first_stop_seconds, plan.missing_rates = _estimate(plan, rates, costed)
    return plans


def _plan_preset(experiment: str, profile: str, runs_dir: str, count_records: bool,
                 overrides: tuple[str, ...] = ()) -> PresetPlan:
    """``overrides``: ``key=value`` settings (a sweep value, ``precision``, ``time_limit_min``); those
    that change a result name the run dir's variant as Hydra's ``override_dirname`` does
    (conf/config.yaml: sorted, comma-joined, excluded keys left out)."""
    first = preset_config(experiment, profile, runs_dir, overrides)
    trials, records = [], records_dir_for(runs_dir)
    for seed in range(first.budget.trials):
        # the seed is a plain field that no other value interpolates: replace() equals composing seed=k
        cfg = dataclasses.replace(first, seed=seed)
        variant = variant_name(cfg.variant, ",".join(variant_overrides(overrides)), cfg.env.backend)
        path = run_dir_path(runs_dir, experiment, variant, seed)
        cfg_hash, key = config_hash(cfg), path.relative_to(runs_dir)
        done = Run(path).is_done(cfg_hash)
        at, source = (0, "") if done else _resume_point(cfg, path, partial_record(records, key, cfg_hash), cfg_hash)
        lost = 0 if done else recorded_attempt(records / PENDING_DIR / key, cfg_hash) or 0
        trials.append(Trial(seed, path, done, cfg, is_recorded(records, key, cfg_hash), at, source,
                            Schedule.of(cfg).iterations if source or lost else 0, _checkpoints_left(cfg, at),
                            lost if lost > at else 0))
    rl = runner_spec(first.runner).trains_policy
    return PresetPlan(experiment, first.env.name, first.runner, trials,
                      first.budget.train_env_steps if rl else 0, overrides=overrides, count_records=count_records)


def _resume_point(cfg: Config, path: Path, partial: Path | None, cfg_hash: str) -> tuple[int, str]:
    """(iteration, where) of the checkpoint an unfinished trial resumes from, as the runner picks
    it (``records.restore.seed_from_partial``): its own run dir's checkpoint of this config, else a
    partial record of this config; (0, "") when it starts afresh or its runner carries none."""
    spec = runner_spec(cfg.runner)
    if spec.load_resume_files is None:
        return 0, ""
    if Run(path).identity() == cfg_hash:
        local = spec.load_resume_files()(path)
        if local is not None:
            return local[1], "run dir"
    if partial is not None:
        return partial_iteration(partial) or 0, "partial record"
    return 0, ""


def _burst_share(cfg: Config, at: int) -> float:
    """The share of a trial's learning left at iteration ``at`` that its runner's one-off burst
    (``RunnerSpec.burst``: DBC's init_steps updates) adds to its first checkpoint interval; 0 when
    the burst is not in that interval (a fresh pixel DBC trial checkpoints after its first episode
    of random acting, so its burst comes later and its time limit stops it before, train/loop.py)."""
    spec = runner_spec(cfg.runner)
    if spec.burst is None:
        return 0.0
    where, size = spec.burst(cfg)
    schedule = Schedule.of(cfg)
    first = _episode_iterations(cfg, schedule) if spec.checkpoints_at == "episode" else 1
    return size / (schedule.iterations - at) if at <= where < at + first else 0.0


def _episode_iterations(cfg: Config, schedule: Schedule) -> int:
    """Iterations in one episode of a learner's one env: its checkpoint spacing when it
    checkpoints at episode ends (``RunnerSpec.checkpoints_at == "episode"``)."""
    return math.ceil(cfg.env.max_episode_steps / schedule.env_steps_per_iteration)


def _checkpoints_left(cfg: Config, at: int) -> int:
    """Checkpoints a time-limited learner resuming at iteration ``at`` (0: fresh) still makes after
    it starts: every iteration, or at the end of each episode of its one env and at each
    evaluation (``RunnerSpec.checkpoints_at``); 0 for the runners that run to their end. A fresh
    run's checkpoint at iteration 0 comes before any training, so it is not one of them."""
    spec = runner_spec(cfg.runner)
    if not spec.time_limited:
        return 0
    schedule = Schedule.of(cfg)
    if spec.checkpoints_at == "episode":  # a resumed run starts a fresh episode at ``at``, as a fresh run at 0
        episode = _episode_iterations(cfg, schedule)
        return sum((i - at) % episode == 0 or schedule.eval_at(i) for i in range(at + 1, schedule.iterations + 1))
    return schedule.iterations - at


# --------------------------------------------------------------------------- cost estimates
def _estimate(plan: PresetPlan, rates: dict[str, float],
              costed: set[str]) -> tuple[dict[int, float], dict[int, float], list[str]]:
    """Seconds of compute of each pending trial by seed (a shared artifact counted once, in the
    first trial that needs it; a trial with a rate never measured has none), the seconds until its
    first stop (time-limited learners: the artifacts it builds first, then its training and
    evaluations spread evenly over its checkpoints, plus a burst its first interval holds; other
    trials run to their end, so all of their estimate), and the rate keys with no measured rate."""
    per_trial, first_stop, missing = {}, {}, set()
    for trial in plan.pending:
        work = _workload(trial.cfg, costed, trial.remaining)
        unknown = {key for key, _ in work if key not in rates}
        if unknown:
            missing |= unknown
            continue
        seconds = {key: amount / rates[key] for key, amount in work}
        per_trial[trial.seed] = sum(seconds.values())
        if trial.checkpoints > 0:
            keys = rate_keys(trial.cfg)
            learning = {keys["train"], keys["eval"]}
            upfront = sum(v for key, v in seconds.items() if key not in learning)
            learning_s = sum(seconds[key] for key in learning)
            share = 1.0 / trial.checkpoints + _burst_share(trial.cfg, trial.resumes_at)
            first_stop[trial.seed] = upfront + learning_s * share
        else:
            first_stop[trial.seed] = per_trial[trial.seed]
    return per_trial, first_stop, sorted(missing)


def _workload(cfg: Config, costed: set[str], remaining: float = 1.0) -> list[tuple[str, float]]:
    """(rate key, amount) pairs: env steps, training samples, or runs (for fixed-cost studies);
    ``remaining``: the fraction of policy training (and its evaluations) a resumed trial has left."""
    from plls_bench.data import dataset_key  # lazy: imports the simulators' wrappers

    budget, keys, work, spec = cfg.budget, rate_keys(cfg), [], runner_spec(cfg.runner)
    data_steps = budget.data_episodes * budget.data_steps_per_episode
    trained = [which for which in ("state", "action") if f"repr_{which}" in keys
               and _first(costed, cfg.runs_dir, f"repr_{which}", _repr_identity(cfg, which))]
    # a recorded V_s / V_a is restored, not trained: it needs no dataset
    if (spec.uses_dataset or trained) and _first(costed, cfg.runs_dir, "data", dataset_key(cfg)):
        work.append((keys["collect"], data_steps))
    for which in trained:
        work.append((keys[f"repr_{which}"], data_steps * cfg.env.data_train_fraction * budget.epochs_for(which)))
    if "train" in keys:
        work += [(keys["train"], budget.train_env_steps * remaining), (keys["eval"], _eval_env_steps(cfg) * remaining)]
    if "run" in keys:
        work.append((keys["run"], 1))
    return work


def _eval_env_steps(cfg: Config) -> int:
    """Upper bound: every evaluation of the trainer's schedule runs full-length test episodes."""
    budget = cfg.budget
    episode = budget.eval_max_steps * cfg.env.action_repeat if budget.eval_max_steps else cfg.env.max_episode_steps
    return Schedule.of(cfg).evaluations * budget.eval_episodes * episode


def _repr_identity(cfg: Config, which: str) -> dict[str, Any]:
    return repr_key(cfg, which)


def _first(costed: set[str], runs_dir: str, kind: str, key: dict[str, Any]) -> bool:
    """True the first time this plan meets an artifact that is not built yet (it is built once,
    then shared)."""
    ident = f"{kind}:{stable_hash(key)}"
    if ident in costed or is_built(runs_dir, kind, key) or recorded_artifact(runs_dir, kind, stable_hash(key)):
        return False
    costed.add(ident)
    return True
