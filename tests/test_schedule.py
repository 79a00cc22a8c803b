"""The one training schedule (``train/schedule.py``): PPO and DBC run it, and the dry run costs
the evaluations it holds."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from plls_bench.pipeline.plan import plan_profile
from plls_bench.rundirs.run_dir import Run
from plls_bench.train.dbc import DBCTrainer
from plls_bench.train.loop import Progress
from plls_bench.train.schedule import Schedule
from tests.conftest import compose_preset


@pytest.mark.parametrize(("iterations", "every"), [(10, 3), (12, 4), (1, 5), (7, 1)])
def test_evaluations_at_zero_every_interval_and_the_last_iteration(iterations: int, every: int) -> None:
    schedule = Schedule(iterations, every, env_steps_per_iteration=1)
    due = [i for i in range(iterations + 1) if schedule.eval_at(i)]
    assert due[0] == 0 and due[-1] == iterations and all(i % every == 0 for i in due[:-1])
    assert [schedule.evaluations_through(i) for i in range(iterations + 1)] == \
        [sum(schedule.eval_at(j) for j in range(i + 1)) for i in range(iterations + 1)]
    assert schedule.evaluations == len(due)


def test_dbc_iterations_are_agent_steps_and_it_evaluates_on_the_schedule(runs_dir: Path) -> None:
    cfg = compose_preset("cheetah_dbc", runs_dir, "budget=quick")
    schedule = Schedule.of(cfg)
    per_eval = cfg.budget.eval_every_env_steps // cfg.env.action_repeat
    assert schedule.env_steps_per_iteration == cfg.env.action_repeat and schedule.eval_every == per_eval
    assert schedule.iterations == cfg.budget.train_env_steps // cfg.env.action_repeat
    trainer = DBCTrainer(cfg, Run(runs_dir / "unused"))
    assert trainer.iterations == schedule.iterations
    assert [i for i in range(schedule.iterations + 1) if trainer.eval_due(Progress(iteration=i))] == \
        [i for i in range(schedule.iterations + 1) if schedule.eval_at(i)]


def test_an_interval_is_rounded_down_to_whole_iterations(runs_dir: Path) -> None:
    cfg = compose_preset("cheetah_dbc", runs_dir, "env.action_repeat=4", "budget.eval_every_env_steps=10")
    assert Schedule.of(cfg).eval_every == 2  # 10 frames: every 2 agent steps of 4 frames


def test_the_dry_run_costs_the_evaluations_of_the_schedule(runs_dir: Path) -> None:
    rates = {"train/cheetah_dbc": 1.0, "eval/cheetah_dbc": 1.0}
    plan = plan_profile("quick", str(runs_dir), only=["cheetah_dbc"], rates=rates, count_records=False)[0]
    cfg = plan.trials[0].cfg
    budget, episode = cfg.budget, cfg.env.max_episode_steps
    assert budget.eval_max_steps == 0 or budget.eval_max_steps * cfg.env.action_repeat == episode
    per_trial = budget.train_env_steps + Schedule.of(cfg).evaluations * budget.eval_episodes * episode
    assert plan.seconds == pytest.approx(len(plan.trials) * per_trial)


def test_a_resumed_dbc_trial_counts_its_episodes_from_the_resume(runs_dir: Path) -> None:
    """A resumed DBC run starts a fresh training episode, so its episode ends fall every episode
    after the resume point, not on the fresh run's grid; evaluations stay on theirs."""
    from plls_bench.pipeline.plan import _checkpoints_left

    cfg = compose_preset("cheetah_dbc", runs_dir, "budget=quick")
    schedule = Schedule.of(cfg)
    episode = cfg.env.max_episode_steps // cfg.env.action_repeat
    assert _checkpoints_left(cfg, 4 * episode) == schedule.iterations // episode - 4  # at an episode end
    at = 4 * episode + 100  # resumed from a checkpoint inside an episode
    ends = set(range(at + episode, schedule.iterations + 1, episode))
    evaluations = {i for i in range(at + 1, schedule.iterations + 1) if schedule.eval_at(i)}
    assert evaluations - ends and _checkpoints_left(cfg, at) == len(ends | evaluations)


def test_the_dry_run_estimates_each_trials_first_checkpoint(runs_dir: Path) -> None:
    """DBC checkpoints at the end of each training episode and at each evaluation (cheetah's
    evaluations fall on episode ends): a fresh quick trial's first checkpoint comes after one
    episode's share of its training and evaluations (not after the checkpoint at iteration 0).
    PPO checkpoints every iteration. Neither preset builds an artifact here (no V_s / V_a)."""
    rates = {"train/cheetah_dbc": 1.0, "eval/cheetah_dbc": 1.0}
    plan = plan_profile("quick", str(runs_dir), only=["cheetah_dbc"], rates=rates, count_records=False)[0]
    trial = plan.trials[0]
    schedule = Schedule.of(trial.cfg)
    episode = trial.cfg.env.max_episode_steps // trial.cfg.env.action_repeat
    assert schedule.eval_every % episode == 0 and trial.checkpoints == schedule.iterations // episode == 100
    assert plan.first_stop_seconds[0] == pytest.approx(plan.trial_seconds[0] / trial.checkpoints)
    rates = {"train/mountaincar_ppo": 2.0, "eval/mountaincar_ppo": 3.0}
    plan = plan_profile("quick", str(runs_dir), only=["mountaincar_ppo"], rates=rates, count_records=False)[0]
    trial = plan.trials[0]
    assert trial.checkpoints == Schedule.of(trial.cfg).iterations
    assert plan.first_stop_seconds[0] == pytest.approx(plan.trial_seconds[0] / trial.checkpoints)


def test_a_first_checkpoint_comes_after_the_artifacts_the_trial_builds(runs_dir: Path) -> None:
    """PL-LS's first trial collects the dataset and trains V_a before any PPO iteration: all of it
    comes before its first checkpoint; the second trial reuses them."""
    from plls_bench.pipeline.rates import rate_keys

    cfg = compose_preset("mountaincar_plls_ppo", runs_dir, "budget=quick")
    rates = {key: 1.0 for key in rate_keys(cfg).values()}
    plan = plan_profile("quick", str(runs_dir), only=["mountaincar_plls_ppo"], rates=rates, count_records=False)[0]
    first, second = plan.trials[:2]
    learning = plan.trial_seconds[second.seed]  # no artifacts left to build
    upfront = plan.trial_seconds[first.seed] - learning
    assert upfront > 0
    assert plan.first_stop_seconds[first.seed] == pytest.approx(upfront + learning / first.checkpoints)
    assert plan.first_stop_seconds[second.seed] == pytest.approx(learning / second.checkpoints)


def test_a_runner_that_runs_to_its_end_first_stops_at_its_end(runs_dir: Path) -> None:
    """Collection has no checkpoint: the launch may start it only with time left for all of it."""
    from plls_bench.pipeline.rates import rate_keys

    cfg = compose_preset("mountaincar_data", runs_dir, "budget=quick")
    rates = {key: 1.0 for key in rate_keys(cfg).values()}
    plan = plan_profile("quick", str(runs_dir), only=["mountaincar_data"], rates=rates, count_records=False)[0]
    trial = plan.trials[0]
    assert trial.checkpoints == 0 and plan.trial_seconds[0] > 0
    assert plan.first_stop_seconds[0] == plan.trial_seconds[0]


def test_a_dbc_trial_resuming_before_its_burst_first_stops_after_it(runs_dir: Path) -> None:
    """A trial resumed at agent step 1000 = init_steps (as stop 42's seed 2 was): its first interval
    holds the burst of 1000 updates, 1000 of its 49,000 iterations' learning left (50,000 agent steps
    at the launcher's action repeat 2), on top of one interval's share. A fresh trial's first interval
    (an episode of random acting, 500 agent steps) does not hold it."""
    from plls_bench.pipeline.plan import _burst_share
    from plls_bench.rundirs.record_layout import PARTIAL_DIR, PARTIAL_MARKER
    from plls_bench.rundirs.run_dir import config_hash

    cfg = compose_preset("cheetah_dbc", runs_dir, "budget=quick")
    assert [_burst_share(cfg, at) for at in (0, 500, 1001)] == [0.0, 0.0, 0.0]
    assert _burst_share(cfg, 1000) == pytest.approx(1000 / 49000) and _burst_share(cfg, 501) > 0
    assert _burst_share(compose_preset("mountaincar_ppo", runs_dir, "budget=quick"), 0) == 0.0
    marker = runs_dir.parent / "records" / PARTIAL_DIR / "cheetah_dbc" / "default" / "seed=0" / PARTIAL_MARKER
    marker.parent.mkdir(parents=True)
    marker.write_text(json.dumps({"config_hash": config_hash(cfg), "iteration": 1000}))
    rates = {"train/cheetah_dbc": 1.0, "eval/cheetah_dbc": 1.0}
    plan = plan_profile("quick", str(runs_dir), only=["cheetah_dbc"], rates=rates)[0]
    resumed, fresh = plan.trials[0], plan.trials[1]
    assert resumed.resumes_at == 1000 and resumed.resumes_from == "partial record" and fresh.resumes_at == 0
    share = 1 / resumed.checkpoints + 1000 / 49000
    assert plan.first_stop_seconds[0] == pytest.approx(plan.trial_seconds[0] * share)
    assert plan.first_stop_seconds[1] == pytest.approx(plan.trial_seconds[1] / fresh.checkpoints)
