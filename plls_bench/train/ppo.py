"""Runner ``ppo``: stable-baselines3 PPO, plain or through the frozen V_s / V_a (PL-LS).

:class:`PPOTrainer` runs in the training skeleton (:mod:`plls_bench.train.loop`). One iteration
is one PPO rollout of ``n_envs x n_steps`` steps and its update, followed by its
``metrics/train.jsonl`` row, an evaluation when due (``metrics/eval.jsonl``) and a checkpoint.
Training envs are reset on a resume (with a seed derived from the checkpoint's iteration):
episodes in flight at the kill are started again.
"""
from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import VecEnv

from plls_bench.config import Config
from plls_bench.core.metric_rows import EvalRow, TrainRow
from plls_bench.core.seeding import derive_seeds, sub_seed
from plls_bench.envs.evaluation import run_episodes
from plls_bench.repr.accounting import architecture_summary, parameter_counts
from plls_bench.repr.build_run import model_test_metrics
from plls_bench.repr.store import ensure_representations
from plls_bench.rundirs.devices import resolve_device
from plls_bench.rundirs.run_dir import ARCHITECTURE_FILE, PARAMS_FILE, Run
from plls_bench.train import checkpoint, loop, normalize
from plls_bench.train.loop import Progress
from plls_bench.train.ppo_model import accounting, build_vec_env, load_model, new_model, sb3_metrics
from plls_bench.train.schedule import Schedule

_EVAL_SAMPLING = 1  # sub-stream of the eval seed for stochastic test actions


class EpisodeStats(BaseCallback):
    """Returns and lengths of the training episodes that end during one rollout."""

    def __init__(self) -> None:
        super().__init__()
        self.returns: list[float] = []
        self.lengths: list[int] = []
        self.rollout_end = 0.0      # perf_counter at the end of the last rollout
        self.rollout_end_cpu = 0.0  # process_time then: the benches cost rollouts in CPU seconds

    def _on_rollout_start(self) -> None:
        self.returns, self.lengths = [], []

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            if "episode" in info:
                self.returns.append(float(info["episode"]["r"]))
                self.lengths.append(int(info["episode"]["l"]))
        return True

    def _on_rollout_end(self) -> None:
        self.rollout_end, self.rollout_end_cpu = time.perf_counter(), time.process_time()

    def summary(self) -> dict[str, float]:
        if not self.returns:
            return {"rollout/episodes": 0}
        return {"rollout/episodes": len(self.returns),
                "rollout/ep_return_mean": sum(self.returns) / len(self.returns),
                "rollout/ep_length_mean": sum(self.lengths) / len(self.lengths)}


class PPOTrainer:
    """PPO in the training skeleton (:mod:`plls_bench.train.loop`). One iteration is one PPO
    rollout of ``n_envs x n_steps`` vector-env steps and its update; a checkpoint after each."""

    unit = "iter"

    def __init__(self, cfg: Config, run: Run) -> None:
        assert cfg.algo.ppo is not None
        self.cfg, self.run, self.ppo, self.schedule = cfg, run, cfg.algo.ppo, Schedule.of(cfg)
        self.seeds = derive_seeds(cfg.seed, cfg.data_seed, cfg.repr.per_trial)
        self.iterations = self.schedule.iterations

    def setup(self) -> None:
        cfg, ppo = self.cfg, self.ppo
        reprs = ensure_representations(cfg)  # V_s / V_a built if missing, loaded once for both envs
        if reprs.artifacts and not (self.run.metrics_dir / "repr_test.json").is_file():  # first start only
            self.run.write_json("metrics/repr_test.json", model_test_metrics(reprs))  # each N_e's V_a MSE (ablations)
        self.train_env = normalize.wrap_training(build_vec_env(cfg, ppo.n_envs, self.seeds.train, reprs), ppo)
        self.eval_env = normalize.wrap_frozen(build_vec_env(cfg, min(ppo.eval_envs, cfg.budget.eval_episodes),
                                                            self.seeds.eval, reprs), ppo)

    def restore(self) -> Progress | None:
        self.model, saved, fresh = _start_or_resume(self.cfg, self.run, self.train_env, self.seeds.train)
        if fresh:
            return None
        return replace(saved, evaluations=self.schedule.evaluations_through(saved.iteration))

    def start(self, at: Progress, resumed: bool) -> None:
        self.model.set_logger(configure(str(self.run.path / "sb3" / f"start={at.iteration:07d}"),
                                        ["csv", "tensorboard"]))
        _write_accounting(self.run, self.model, self.train_env)
        self.stats = EpisodeStats()

    def train_iteration(self, at: Progress) -> tuple[Progress, dict[str, Any]]:
        start = time.perf_counter()
        self.model.learn(self.schedule.env_steps_per_iteration // self.cfg.env.action_repeat, callback=self.stats,
                         log_interval=None, reset_num_timesteps=False)
        steps = int(self.model.num_timesteps)
        done = replace(at, iteration=at.iteration + 1, agent_steps=steps,
                       env_steps=steps * self.cfg.env.action_repeat)
        seconds = time.perf_counter() - start
        return done, {**sb3_metrics(self.model.logger.name_to_value), **self.stats.summary(),
                      "perf/sps": self.schedule.env_steps_per_iteration / seconds,
                      "perf/rollout_s": self.stats.rollout_end - start,
                      "perf/update_s": time.perf_counter() - self.stats.rollout_end}

    def eval_due(self, at: Progress) -> bool:
        return self.schedule.eval_at(at.iteration)

    def evaluate(self, at: Progress) -> EvalRow:
        """Deterministic and stochastic test episodes (the same seeds at every evaluation); the
        stochastic ones sample from their own torch stream, so evaluating never shifts training's.
        With VecNormalize, the test env gets the training statistics frozen at this point."""
        model, venv, seeds = self.model, self.eval_env, self.seeds
        n, cap = self.cfg.budget.eval_episodes, self.cfg.budget.eval_max_steps
        normalize.sync(model.get_env(), venv)
        greedy = run_episodes(venv, lambda obs: model.predict(obs, deterministic=True)[0], n, seeds.eval, cap)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(sub_seed(seeds.eval, _EVAL_SAMPLING, at.iteration))
            sampled = run_episodes(venv, lambda obs: model.predict(obs, deterministic=False)[0], n, seeds.eval, cap)
        return EvalRow.at(at, episode_returns=greedy.returns, episode_lengths=greedy.lengths,
                          return_mean=_mean(greedy.returns), episode_returns_stochastic=sampled.returns,
                          episode_lengths_stochastic=sampled.lengths, return_mean_stochastic=_mean(sampled.returns))

    def report(self, at: Progress, row: TrainRow | None, evaluation: EvalRow | None) -> None:
        """SB3's logger gets each iteration's numbers (none for the evaluation before training)."""
        if row is not None:
            extra = {} if evaluation is None else {"eval/return_mean": evaluation.return_mean,
                                                   "eval/return_mean_stochastic": evaluation.return_mean_stochastic}
            _dump_to_sb3(self.model, {**row.metrics, **extra}, at)

    def checkpoint_due(self, at: Progress, evaluated: bool) -> bool:
        return True

    def interval_ahead_s(self, at: Progress) -> float:
        """Every PPO iteration is alike: the last ones say it."""
        return 0.0

    def checkpoint(self, at: Progress) -> None:
        checkpoint.save(self.run, self.model, at, normalize.state_json(self.train_env))

    def close(self) -> None:
        self.train_env.close()
        self.eval_env.close()


def run(cfg: Config, run: Run) -> None:
    """Train PPO for ``budget.train_env_steps``, evaluating every ``budget.eval_every_env_steps``."""
    loop.train(PPOTrainer(cfg, run), run, cfg)


def _start_or_resume(cfg: Config, run: Run, venv: VecEnv, train_seed: int) -> tuple[PPO, Progress, bool]:
    """A new model (fresh: True), or the last checkpoint with its RNG states, ``venv`` reseeded
    from the checkpoint's iteration and its VecNormalize statistics restored."""
    found = checkpoint.latest(run.path)
    if found is None:
        return new_model(cfg, venv), Progress(), True
    zip_path, saved_progress, rng = found
    saved = checkpoint.restored_progress(saved_progress, cfg.env.action_repeat)
    venv.seed(sub_seed(train_seed, saved.iteration))
    saved_stats = checkpoint.normalization(run.path)
    if saved_stats is not None:
        normalize.restore(venv, saved_stats)
    # under quiet_rng: the checkpoint's RNG states follow
    model = load_model(zip_path, resolve_device(cfg.device), venv)
    checkpoint.set_rng_state(rng)
    return model, saved, False


def _dump_to_sb3(model: PPO, record: dict[str, Any], at: Progress) -> None:
    """SB3's logger (CSV + TensorBoard under ``sb3/``) gets the same numbers as ``train.jsonl``
    and the evaluation's means; SB3's own ``train/*`` values are already recorded by its update."""
    for key, value in record.items():
        if "/" in key and not key.startswith(("train/", "loss/")):
            model.logger.record(key, value)
    model.logger.record("time/iteration", at.iteration)
    model.logger.dump(step=at.agent_steps)


def _write_accounting(run: Run, model: PPO, venv: VecEnv) -> None:
    modules, examples = accounting(model, venv)
    run.write_json(PARAMS_FILE, parameter_counts(modules, trainable=["policy"]))
    with torch.random.fork_rng(devices=[]):  # the policy's forward samples an action
        run.write_json(ARCHITECTURE_FILE, architecture_summary(modules, examples))


def _mean(values: list[float]) -> float:
    return sum(values) / len(values)
