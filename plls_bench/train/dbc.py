"""Runner ``dbc``: DBC (and PL-LS + DBC) on cheetah-run from pixels.

The agent acts in an SB3 ``VecEnv`` of one env; with ``repr/action=vae`` that env is wrapped by
the latent-action wrapper, so PL-LS + DBC is this same code acting in V_a's latent space. The loop
follows the reference's train.py: ``init_steps`` uniform random agent steps, then one update per
agent step (``init_steps`` of them at once at the first learning step), the update before the
env step. Every ``budget.eval_every_env_steps`` env steps (frames, counting action repeat) the
deterministic policy is evaluated on ``budget.eval_episodes`` fresh episodes of a separately
seeded env, then the run is checkpointed (see :mod:`plls_bench.train.dbc_state`).
"""
from __future__ import annotations

import logging
import math
import time

import numpy as np
from stable_baselines3.common.vec_env import VecEnv
from tqdm.auto import tqdm

from baselines.dbc import DBCAgent, FrameReplay
from plls_bench.config import Config
from plls_bench.devices import resolve_device
from plls_bench.envs import make_vec_env
from plls_bench.evaluate import run_episodes
from plls_bench.latent import wrap_latent
from plls_bench.repr.store import Representations, ensure_representations
from plls_bench.runs import Run
from plls_bench.seeding import derive_seeds
from plls_bench.train.dbc_accounting import write_accounting
from plls_bench.train.dbc_state import Progress, load_checkpoint, save_checkpoint

log = logging.getLogger(__name__)


def make_envs(cfg: Config, train_seed: int, reprs: Representations) -> tuple[VecEnv, VecEnv]:
    """The training and evaluation VecEnvs (one env each), through the latent wrappers: with
    ``repr/action=vae`` the agent acts in V_a's latent box (PL-LS + DBC), else they are unchanged.
    The evaluation env is re-seeded at every evaluation."""
    reprs.check(cfg)
    train, evaluation = (wrap_latent(make_vec_env(cfg.env, 1, seed), reprs) for seed in (train_seed, train_seed + 1))
    return train, evaluation


def to_env_action(action: np.ndarray, space) -> np.ndarray:
    """Agent actions ``(N, A)`` in [-1, 1] -> the env's action box (V_a's latent box when wrapped)."""
    return (space.low + (action + 1.0) * 0.5 * (space.high - space.low)).astype(space.dtype)


def _stream_seed(seed: int, index: int) -> int:
    return int(np.random.SeedSequence([seed, index]).generate_state(1)[0])


class Window:
    """Running means of update metrics and rates between two ``train.jsonl`` records."""

    def __init__(self, progress: Progress) -> None:
        self.sums: dict[str, float] = {}
        self.counts: dict[str, int] = {}
        self.returns: list[float] = []
        self.updates = 0
        self.agent_steps0, self.env_steps0, self.t0 = progress.agent_steps, progress.env_steps, time.perf_counter()

    def add(self, metrics: dict[str, float]) -> None:
        self.updates += 1
        for key, value in metrics.items():
            self.sums[key] = self.sums.get(key, 0.0) + value
            self.counts[key] = self.counts.get(key, 0) + 1

    def record(self, progress: Progress) -> dict[str, float | list[float]]:
        seconds = max(time.perf_counter() - self.t0, 1e-9)
        return {**{k: self.sums[k] / self.counts[k] for k in self.sums}, "train/episode_returns": self.returns,
                "perf/updates_per_s": self.updates / seconds,
                "perf/env_steps_per_s": (progress.env_steps - self.env_steps0) / seconds}


class DBCTrainer:
    """One DBC run: envs, agent, replay and the loop; resumes from the run's checkpoint. ``reprs``
    holds the run's V_a (PL-LS + DBC), loaded by the caller's setup."""

    def __init__(self, cfg: Config, run: Run, reprs: Representations) -> None:
        self.cfg, self.run, self.dbc = cfg, run, cfg.algo.dbc
        self.seeds = derive_seeds(cfg.seed, cfg.data_seed, cfg.repr.per_trial)
        self.device = resolve_device(cfg.device)
        self.train_env, self.eval_env = make_envs(cfg, self.seeds.train, reprs)
        obs_shape = self.train_env.observation_space.shape
        self.action_dim = int(np.prod(self.train_env.action_space.shape))
        repeat = cfg.env.action_repeat
        self.total_agent_steps = math.ceil(cfg.budget.train_env_steps / repeat)
        self.agent = DBCAgent(obs_shape, self.action_dim, self.dbc, self.device)
        self.replay = FrameReplay(obs_shape, cfg.env.frame_stack if cfg.env.pixels else 1, self.action_dim,
                                  capacity=min(self.dbc.replay_capacity, self.total_agent_steps),
                                  episode_length=math.ceil(cfg.env.max_episode_steps / repeat))
        budget = cfg.budget
        self.eval_points = [*range(0, budget.train_env_steps, budget.eval_every_env_steps), budget.train_env_steps]
        self.rng = np.random.default_rng(self.seeds.train)
        self.progress = load_checkpoint(run, self.agent, self.replay, self.rng) or Progress()
        log.info("replay: %d slots, %.1f MiB (%d bytes/transition; reference layout %d bytes/transition)",
                 self.replay.slots, self.replay.nbytes / 2**20, self.replay.bytes_per_slot(),
                 self.replay.reference_bytes_per_transition())

    def eval_due(self) -> bool:
        """Evaluations happen at 0, every, 2 * every, ... env steps and at the end of training."""
        n = self.progress.evaluations
        return n < len(self.eval_points) and self.progress.env_steps >= self.eval_points[n]

    def train(self) -> None:
        done_before = self.progress.env_steps
        keep = (lambda r: r.get("env_steps", -1) <= done_before) if self.progress.evaluations else (lambda r: False)
        for stream in ("eval", "train"):
            self.run.truncate_metrics(stream, keep)
        write_accounting(self.run, self.agent, self.train_env)
        self.t_start, self.wall0 = time.perf_counter(), self.progress.wall_s
        if self.progress.evaluations:  # resumed: the interrupted episode is not continued
            self.train_env.seed(_stream_seed(self.seeds.train, self.progress.agent_steps))
        obs = self.train_env.reset()
        self.replay.start_episode(obs[0])
        window, episode_return = Window(self.progress), 0.0
        bar = tqdm(total=self.total_agent_steps, initial=self.progress.agent_steps, disable=not self.cfg.progress,
                   desc=f"dbc {self.cfg.experiment} seed={self.cfg.seed}", unit="step")
        while True:
            if self.eval_due():
                self._log_train(window)
                self._evaluate_and_checkpoint()
                window = Window(self.progress)  # rates exclude evaluation time
            if self.progress.agent_steps >= self.total_agent_steps:
                break
            obs, reward, finished = self.step(obs, window)
            episode_return += reward
            if finished:  # one train.jsonl record per training episode (and one before each eval)
                window.returns.append(episode_return)
                self._log_train(window)
                window, episode_return = Window(self.progress), 0.0
            bar.update(1)
        bar.close()

    def step(self, obs: np.ndarray, window: Window | None = None,
             updates: bool = True) -> tuple[np.ndarray, float, bool]:
        """One agent step from observation ``(1, *O)``: act, update (unless ``updates`` is False),
        step the env, store the transition. Returns the next observation, reward and done."""
        step, init = self.progress.agent_steps, self.dbc.init_steps
        if step < init:
            action = self.rng.uniform(-1.0, 1.0, size=(1, self.action_dim)).astype(np.float32)
        else:
            action = self.agent.act(obs, deterministic=False)
        if step >= init and updates:
            for _ in range(init if step == init else 1):
                batch = self.replay.sample(self.dbc.batch_size, self.rng, self.device)
                metrics = self.agent.update(batch, step)
                if window is not None:
                    window.add(metrics)
        next_obs, reward, done, info = self.train_env.step(to_env_action(action, self.train_env.action_space))
        terminated = bool(done[0]) and not info[0].get("TimeLimit.truncated", False)
        final = info[0]["terminal_observation"] if done[0] else next_obs[0]
        self.replay.add(action[0], float(reward[0]), terminated, final)
        if done[0]:
            self.replay.start_episode(next_obs[0])
            self.progress.episodes += 1
        self.progress.agent_steps += 1
        self.progress.env_steps += self.cfg.env.action_repeat
        return next_obs, float(reward[0]), bool(done[0])

    def _wall(self) -> float:
        return self.wall0 + time.perf_counter() - self.t_start

    def _counters(self) -> dict[str, float]:
        p = self.progress
        return {"env_steps": p.env_steps, "iteration": p.agent_steps, "agent_steps": p.agent_steps,
                "wall_s": round(self._wall(), 3)}

    def _log_train(self, window: Window) -> None:
        if self.progress.agent_steps > window.agent_steps0:
            self.run.log("train", {**self._counters(), **window.record(self.progress)})

    def _evaluate_and_checkpoint(self) -> None:
        p = self.progress
        def act(obs: np.ndarray) -> np.ndarray:
            return to_env_action(self.agent.act(obs, deterministic=True), self.eval_env.action_space)

        budget = self.cfg.budget
        episodes = run_episodes(self.eval_env, act, budget.eval_episodes,
                                _stream_seed(self.seeds.eval, p.evaluations), budget.eval_max_steps)
        returns, lengths = episodes.returns, episodes.lengths
        self.run.log("eval", {**self._counters(), "episode_returns": returns, "episode_lengths": lengths,
                              "return_mean": float(np.mean(returns))})
        log.info("eval at %d env steps: return %.1f", p.env_steps, float(np.mean(returns)))
        p.evaluations += 1
        p.wall_s = self._wall()
        save_checkpoint(self.run, self.agent, self.replay, p, self.rng)


def run(cfg: Config, run: Run) -> None:
    """Runner ``dbc`` (see module docstring)."""
    trainer = DBCTrainer(cfg, run, ensure_representations(cfg))  # V_a built if missing, loaded once
    try:
        trainer.train()
    finally:
        trainer.train_env.close()
        trainer.eval_env.close()
