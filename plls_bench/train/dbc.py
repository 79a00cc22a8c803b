"""Runner ``dbc``: DBC (and PL-LS + DBC) on cheetah-run from pixels.

The agent acts in an SB3 ``VecEnv`` of one env; with ``repr/action=vae`` that env is wrapped by
the latent-action wrapper, so PL-LS + DBC is this same code acting in V_a's latent space. The loop
follows the reference's train.py: ``init_steps`` uniform random agent steps, then one update per
agent step (``init_steps`` of them at once at the first learning step), the update before the
env step. :class:`DBCTrainer` runs in the training skeleton (:mod:`plls_bench.train.loop`); one
iteration is one agent step. Every ``budget.eval_every_env_steps`` env steps (frames, counting
action repeat; :mod:`plls_bench.train.schedule`) the deterministic policy is evaluated on
``budget.eval_episodes`` fresh episodes of a separately seeded env. The run is checkpointed after
each evaluation and at the end of each training episode (see :mod:`plls_bench.train.dbc_state`).
"""
from __future__ import annotations

import copy
import logging
import math
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.vec_env import VecEnv

from baselines.dbc import DBCAgent, FrameReplay
from plls_bench.config import Config
from plls_bench.core.metric_rows import EvalRow, TrainRow
from plls_bench.core.seeding import derive_seeds, derived_seed
from plls_bench.envs import make_vec_env
from plls_bench.envs.evaluation import run_episodes
from plls_bench.repr.latent_wrappers import wrap_latent
from plls_bench.repr.pixel_trunk import conv_stack
from plls_bench.repr.store import Representations, ensure_representations
from plls_bench.rundirs.devices import resolve_device
from plls_bench.rundirs.run_dir import Run
from plls_bench.train import loop
from plls_bench.train.dbc_accounting import write_accounting
from plls_bench.train.dbc_state import CHECKPOINT, POLICY, load_checkpoint, load_trained_agent, save_checkpoint
from plls_bench.train.loop import Progress
from plls_bench.train.schedule import Schedule
from plls_bench.train.trained_policy import TrainedPolicy

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


class Window:
    """Running means of update metrics and rates between two ``train.jsonl`` records."""

    def __init__(self, at: Progress) -> None:
        self.sums: dict[str, float] = {}
        self.counts: dict[str, int] = {}
        self.returns: list[float] = []
        self.updates = 0
        self.agent_steps0, self.env_steps0, self.t0 = at.agent_steps, at.env_steps, time.perf_counter()

    def add(self, metrics: dict[str, float]) -> None:
        self.updates += 1
        for key, value in metrics.items():
            self.sums[key] = self.sums.get(key, 0.0) + value
            self.counts[key] = self.counts.get(key, 0) + 1

    def record(self, at: Progress) -> dict[str, float | list[float]]:
        seconds = max(time.perf_counter() - self.t0, 1e-9)
        return {**{k: self.sums[k] / self.counts[k] for k in self.sums}, "train/episode_returns": self.returns,
                "perf/updates_per_s": self.updates / seconds,
                "perf/env_steps_per_s": (at.env_steps - self.env_steps0) / seconds}


class DBCTrainer:
    """DBC in the training skeleton (:mod:`plls_bench.train.loop`). One iteration is one agent
    step (``env.action_repeat`` frames) with its updates; a ``train.jsonl`` row per training
    episode and one before each evaluation; a checkpoint after each of them."""

    unit = "step"

    def __init__(self, cfg: Config, run: Run, reprs: Representations | None = None) -> None:
        """``reprs``: V_s / V_a already loaded (the bench scripts); None: ``setup`` builds or loads them."""
        assert cfg.algo.dbc is not None
        self.reprs = reprs
        self.cfg, self.run, self.dbc = cfg, run, cfg.algo.dbc
        self.seeds = derive_seeds(cfg.seed, cfg.data_seed, cfg.repr.per_trial)
        self.schedule = Schedule.of(cfg)
        self.iterations = self.schedule.iterations

    def setup(self) -> None:
        cfg = self.cfg
        self.device = resolve_device(cfg.device)
        reprs = self.reprs or ensure_representations(cfg)  # V_a (PL-LS + DBC) built if missing, loaded once
        self.train_env, self.eval_env = make_envs(cfg, self.seeds.train, reprs)
        obs_shape = self.train_env.observation_space.shape
        self.action_dim = int(np.prod(self.train_env.action_space.shape))
        self.agent = DBCAgent(obs_shape, self.action_dim, self.dbc, self.device, conv_stack(cfg.precision))
        self.episode_steps = math.ceil(cfg.env.max_episode_steps / cfg.env.action_repeat)  # agent steps
        self.replay = FrameReplay(obs_shape, cfg.env.frame_stack if cfg.env.pixels else 1, self.action_dim,
                                  capacity=min(self.dbc.replay_capacity, self.iterations),
                                  episode_length=self.episode_steps)
        self.rng = np.random.default_rng(self.seeds.train)

    def restore(self) -> Progress | None:
        saved = load_checkpoint(self.run, self.agent, self.replay, self.rng)
        log.info("replay: %d slots, %.1f MiB (%d bytes/transition; reference layout %d bytes/transition)",
                 self.replay.slots, self.replay.nbytes / 2**20, self.replay.bytes_per_slot(),
                 self.replay.reference_bytes_per_transition())
        return saved

    def start(self, at: Progress, resumed: bool) -> None:
        write_accounting(self.run, self.agent, self.train_env)
        if resumed:  # the interrupted episode is not continued
            self.train_env.seed(derived_seed((self.seeds.train, at.agent_steps)))
        self.obs = self.train_env.reset()
        self.replay.start_episode(self.obs[0])
        self.window, self.episode_return, self.episode_ended = Window(at), 0.0, False

    def train_iteration(self, at: Progress) -> tuple[Progress, dict[str, Any] | None]:
        """One agent step; the train row's metrics at the end of an episode or before an evaluation."""
        self.obs, reward, finished = self.step(self.obs, at.agent_steps, self.window)
        at = replace(at, iteration=at.iteration + 1, agent_steps=at.agent_steps + 1,
                     env_steps=at.env_steps + self.cfg.env.action_repeat, episodes=at.episodes + finished)
        self.episode_return += reward
        self.episode_ended = finished
        if finished:
            self.window.returns.append(self.episode_return)
            self.episode_return = 0.0
        if not (finished or self.eval_due(at)):
            return at, None
        metrics, self.window = self.window.record(at), Window(at)
        return at, metrics

    def step(self, obs: np.ndarray, step: int, window: Window | None = None,
             updates: bool = True) -> tuple[np.ndarray, float, bool]:
        """Agent step number ``step`` from observation ``(1, *O)``: act, update (unless ``updates``
        is False), step the env, store the transition. Returns the next observation, reward, done."""
        init = self.dbc.init_steps
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
        return next_obs, float(reward[0]), bool(done[0])

    def eval_due(self, at: Progress) -> bool:
        return self.schedule.eval_at(at.iteration)

    def evaluate(self, at: Progress) -> EvalRow:
        """The deterministic policy on fresh episodes of the evaluation env, seeded per evaluation."""
        def act(obs: np.ndarray) -> np.ndarray:
            return to_env_action(self.agent.act(obs, deterministic=True), self.eval_env.action_space)

        budget = self.cfg.budget
        episodes = run_episodes(self.eval_env, act, budget.eval_episodes,
                                derived_seed((self.seeds.eval, at.evaluations)), budget.eval_max_steps)
        mean = float(np.mean(episodes.returns))
        log.info("eval at %d env steps: return %.1f", at.env_steps, mean)
        return EvalRow.at(at, episode_returns=episodes.returns, episode_lengths=episodes.lengths, return_mean=mean)

    def report(self, at: Progress, row: TrainRow | None, evaluation: EvalRow | None) -> None:
        """DBC logs only to ``metrics/``."""

    def checkpoint_due(self, at: Progress, evaluated: bool) -> bool:
        """After each evaluation, and at the end of each training episode: a sitting's deadline
        then costs at most an episode of training (a pixel episode is about 4 minutes on one CPU
        core, an evaluation interval about 50), and a resume drops no part of an episode."""
        return evaluated or self.episode_ended

    def interval_ahead_s(self, at: Progress) -> float:
        """If the burst of ``init_steps`` updates comes before the next episode's end: that many
        updates plus an episode's, at the speed of one update timed now; else 0 (the last intervals
        say it). Without this a sitting's deadline could start the burst, about 20 CPU-minutes,
        after intervals of random acting that took seconds."""
        init, episode = self.dbc.init_steps, self.episode_steps
        if not at.agent_steps <= init < at.agent_steps + episode:
            return 0.0
        if len(self.replay) == 0:  # init_steps shorter than an episode: nothing to time an update on yet
            log.info("the burst of %d updates comes before the first episode's end; not timed", init)
            return 0.0
        seconds = (init + episode) * self._seconds_per_update()
        log.info("the next checkpoint interval holds the burst of %d updates: about %.0f s", init, seconds)
        return seconds

    def _seconds_per_update(self) -> float:
        """The faster of two updates of a throw-away copy of the agent on one minibatch, sampled with
        its own generator and under a forked torch RNG: the run's agent and RNG streams stay as
        they were, so a run with a time limit learns exactly as one without."""
        probe = copy.deepcopy(self.agent)
        batch = self.replay.sample(self.dbc.batch_size, np.random.default_rng(0), self.device)
        timings = []
        with torch.random.fork_rng(devices=[self.device] if self.device.type == "cuda" else []):
            for _ in range(2):
                start = time.perf_counter()
                probe.update(batch, self.dbc.init_steps)
                timings.append(time.perf_counter() - start)
        return min(timings)

    def checkpoint(self, at: Progress) -> None:
        save_checkpoint(self.run, self.agent, self.replay, at, self.rng)
        self.window = Window(at)  # rates exclude evaluation and checkpoint time

    def close(self) -> None:
        self.train_env.close()
        self.eval_env.close()


def run(cfg: Config, run: Run) -> None:
    """Runner ``dbc`` (see module docstring)."""
    loop.train(DBCTrainer(cfg, run), run, cfg)


def trained_policy(run_dir: Path, device: str) -> TrainedPolicy:
    """The run's deterministic actor, from its checkpoint or, in a record, from the actor's weights alone."""
    cfg, agent, space, reprs = load_trained_agent(run_dir, device)
    used = CHECKPOINT if (run_dir / CHECKPOINT).exists() else POLICY  # a record keeps the actor alone
    return TrainedPolicy(cfg, lambda obs: to_env_action(agent.act(obs, deterministic=True), space),
                         Path(used).name, reprs)
