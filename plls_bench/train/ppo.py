"""Runner ``ppo``: stable-baselines3 PPO, plain or through the frozen V_s / V_a (PL-LS).

One iteration is one PPO rollout of ``n_envs x n_steps`` steps and its update. The loop is
``learn`` one iteration -> ``metrics/train.jsonl`` -> evaluate when due -> ``metrics/eval.jsonl`` ->
checkpoint. A checkpoint at iteration k covers every metric row with ``iteration <= k``; a
restarted run drops rows newer than its checkpoint and redoes those iterations, so the eval
history ends complete and without duplicates. Training envs are reset on a resume (with a seed
derived from the checkpoint's iteration): episodes in flight at the kill are started again.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import VecEnv
from tqdm.auto import tqdm

from plls_bench.config import Config
from plls_bench.devices import resolve_device
from plls_bench.evaluate import run_episodes
from plls_bench.repr.accounting import architecture_summary, parameter_counts
from plls_bench.repr.store import ensure_representations
from plls_bench.runs import Run
from plls_bench.seeding import Seeds, derive_seeds, sub_seed
from plls_bench.train import checkpoint, normalize
from plls_bench.train.agent import accounting, build_vec_env, new_model, sb3_metrics
from plls_bench.train.checkpoint import Progress

_EVAL_SAMPLING = 1  # sub-stream of the eval seed for stochastic test actions


@dataclass(frozen=True)
class Plan:
    """The budget in PPO iterations (``budget.*_env_steps`` are env steps, counting action repeat)."""

    iterations: int          # PPO iterations to run
    eval_every: int          # evaluate every this many iterations (and at 0 and the last)
    env_steps_per_iteration: int

    @classmethod
    def of(cls, cfg: Config) -> Plan:
        assert cfg.algo.ppo is not None
        per_iteration = cfg.algo.ppo.steps_per_iteration * cfg.env.action_repeat
        return cls(iterations=math.ceil(cfg.budget.train_env_steps / per_iteration),
                   eval_every=max(1, cfg.budget.eval_every_env_steps // per_iteration),
                   env_steps_per_iteration=per_iteration)

    def eval_at(self, iteration: int) -> bool:
        return iteration % self.eval_every == 0 or iteration == self.iterations


class EpisodeStats(BaseCallback):
    """Returns and lengths of the training episodes that end during one rollout."""

    def __init__(self) -> None:
        super().__init__()
        self.returns: list[float] = []
        self.lengths: list[int] = []
        self.rollout_end = 0.0

    def _on_rollout_start(self) -> None:
        self.returns, self.lengths = [], []

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            if "episode" in info:
                self.returns.append(float(info["episode"]["r"]))
                self.lengths.append(int(info["episode"]["l"]))
        return True

    def _on_rollout_end(self) -> None:
        self.rollout_end = time.perf_counter()

    def summary(self) -> dict[str, float]:
        if not self.returns:
            return {"rollout/episodes": 0}
        return {"rollout/episodes": len(self.returns),
                "rollout/ep_return_mean": sum(self.returns) / len(self.returns),
                "rollout/ep_length_mean": sum(self.lengths) / len(self.lengths)}


def run(cfg: Config, run: Run) -> None:
    """Train PPO for ``budget.train_env_steps``, evaluating every ``budget.eval_every_env_steps``."""
    assert cfg.algo.ppo is not None
    ppo = cfg.algo.ppo
    seeds = derive_seeds(cfg.seed, cfg.data_seed, cfg.repr.per_trial)
    reprs = ensure_representations(cfg)  # V_s / V_a built if missing, loaded once for both envs
    train_env = normalize.wrap_training(build_vec_env(cfg, ppo.n_envs, seeds.train, reprs), ppo)
    n_eval = min(ppo.eval_envs, cfg.budget.eval_episodes)
    eval_env = normalize.wrap_frozen(build_vec_env(cfg, n_eval, seeds.eval, reprs), ppo)
    try:
        _train(cfg, run, Plan.of(cfg), seeds, train_env, eval_env)
    finally:
        train_env.close()
        eval_env.close()


def _train(cfg: Config, run: Run, plan: Plan, seeds: Seeds, train_env: VecEnv, eval_env: VecEnv) -> None:
    model, progress, fresh = _start_or_resume(cfg, run, train_env, seeds.train)
    model.set_logger(configure(str(run.path / "sb3" / f"start={progress.iteration:07d}"), ["csv", "tensorboard"]))
    _write_accounting(run, model, train_env)
    started = time.perf_counter()

    def position(iteration: int) -> Progress:
        wall = progress.wall_s + time.perf_counter() - started
        return Progress(iteration, int(model.num_timesteps), round(wall, 3))

    if fresh:
        _log_eval(cfg, run, model, eval_env, seeds, position(0))
        checkpoint.save(run, model, position(0), normalize.state_json(train_env))
    stats = EpisodeStats()
    with tqdm(total=plan.iterations, initial=progress.iteration, unit="iter", disable=not cfg.progress,
              desc=f"ppo {cfg.experiment} seed={cfg.seed}") as bar:
        for iteration in range(progress.iteration + 1, plan.iterations + 1):
            start = time.perf_counter()
            model.learn(plan.env_steps_per_iteration // cfg.env.action_repeat, callback=stats,
                        log_interval=None, reset_num_timesteps=False)
            done = position(iteration)
            seconds = time.perf_counter() - start
            record = {**_steps(cfg, done), **sb3_metrics(model.logger.name_to_value), **stats.summary(),
                      "perf/sps": plan.env_steps_per_iteration / seconds,
                      "perf/rollout_s": stats.rollout_end - start,
                      "perf/update_s": time.perf_counter() - stats.rollout_end}
            run.log("train", record)
            extra = _log_eval(cfg, run, model, eval_env, seeds, done) if plan.eval_at(iteration) else {}
            _dump_to_sb3(model, {**record, **extra}, done)
            checkpoint.save(run, model, position(iteration), normalize.state_json(train_env))
            bar.set_postfix({k.split("/")[1]: round(v, 2) for k, v in extra.items()}, refresh=False)
            bar.update(1)


def _start_or_resume(cfg: Config, run: Run, venv: VecEnv, train_seed: int) -> tuple[PPO, Progress, bool]:
    """A new model (and empty metric streams), or the last checkpoint with its RNG states."""
    found = checkpoint.latest(run.path)
    if found is None:
        for stream in ("train", "eval"):
            run.truncate_metrics(stream, lambda _: False)
        return new_model(cfg, venv), Progress(0, 0, 0.0), True
    zip_path, progress, rng = found
    for stream in ("train", "eval"):
        run.truncate_metrics(stream, lambda r: r["iteration"] <= progress.iteration)
    venv.seed(sub_seed(train_seed, progress.iteration))
    saved_stats = checkpoint.normalization(run.path)
    if saved_stats is not None:
        normalize.restore(venv, saved_stats)
    model = PPO.load(zip_path, env=venv, device=resolve_device(cfg.device))
    checkpoint.set_rng_state(rng)
    return model, progress, False


def _steps(cfg: Config, at: Progress) -> dict[str, Any]:
    return {"iteration": at.iteration, "agent_steps": at.agent_steps,
            "env_steps": at.agent_steps * cfg.env.action_repeat, "wall_s": at.wall_s}


def _log_eval(cfg: Config, run: Run, model: PPO, venv: VecEnv, seeds: Seeds, at: Progress) -> dict[str, float]:
    """Deterministic and stochastic test episodes (the same seeds at every evaluation); the
    stochastic ones sample from their own torch stream, so evaluating never shifts training's.
    With VecNormalize, the test env gets the training statistics frozen at this point."""
    n, cap = cfg.budget.eval_episodes, cfg.budget.eval_max_steps
    normalize.sync(model.get_env(), venv)
    greedy = run_episodes(venv, lambda obs: model.predict(obs, deterministic=True)[0], n, seeds.eval, cap)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(sub_seed(seeds.eval, _EVAL_SAMPLING, at.iteration))
        sampled = run_episodes(venv, lambda obs: model.predict(obs, deterministic=False)[0], n, seeds.eval, cap)
    mean, mean_sampled = _mean(greedy.returns), _mean(sampled.returns)
    run.log("eval", {**_steps(cfg, at), "episode_returns": greedy.returns, "return_mean": mean,
                     "episode_lengths": greedy.lengths, "episode_returns_stochastic": sampled.returns,
                     "return_mean_stochastic": mean_sampled, "episode_lengths_stochastic": sampled.lengths})
    return {"eval/return_mean": mean, "eval/return_mean_stochastic": mean_sampled}


def _dump_to_sb3(model: PPO, record: dict[str, Any], at: Progress) -> None:
    """SB3's logger (CSV + TensorBoard under ``sb3/``) gets the same numbers as ``train.jsonl``;
    SB3's own ``train/*`` values are already recorded by its update."""
    for key, value in record.items():
        if "/" in key and not key.startswith(("train/", "loss/")):
            model.logger.record(key, value)
    model.logger.record("time/iteration", at.iteration)
    model.logger.dump(step=at.agent_steps)


def _write_accounting(run: Run, model: PPO, venv: VecEnv) -> None:
    modules, examples = accounting(model, venv)
    run.write_json("metrics/params.json", parameter_counts(modules, trainable=["policy"]))
    with torch.random.fork_rng(devices=[]):  # the policy's forward samples an action
        run.write_json("metrics/architecture.json", architecture_summary(modules, examples))


def _mean(values: list[float]) -> float:
    return sum(values) / len(values)
