"""Test episodes on separately seeded vector envs that are never used for learning.

Episode ``j`` of an evaluation is reset with seed ``seed + j``, so every evaluation of a trial
sees the same start states (tracks, car positions): points on a learning curve differ only in
the policy, and a resumed run re-evaluates exactly what an uninterrupted one would have.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from stable_baselines3.common.vec_env import VecEnv

Act = Callable[[np.ndarray], np.ndarray]  # batched observations (n_envs, *O) -> actions (n_envs, *A)


@dataclass(frozen=True)
class Episodes:
    returns: list[float]   # undiscounted return of each episode, in episode order
    lengths: list[int]     # steps of each episode


def run_episodes(venv: VecEnv, act: Act, n_episodes: int, seed: int, max_steps: int = 0) -> Episodes:
    """``n_episodes`` episodes, ``venv.num_envs`` at a time; episode j is seeded ``seed + j``.
    ``max_steps > 0`` cuts episodes after that many steps (smoke budgets only)."""
    returns: list[float] = []
    lengths: list[int] = []
    for start in range(0, n_episodes, venv.num_envs):
        wave = min(venv.num_envs, n_episodes - start)
        wave_returns, wave_lengths = _wave(venv, act, seed + start, wave, max_steps)
        returns += wave_returns
        lengths += wave_lengths
    return Episodes(returns, lengths)


def _wave(venv: VecEnv, act: Act, seed: int, n_active: int, max_steps: int) -> tuple[list[float], list[int]]:
    """One episode in each of the first ``n_active`` envs (env i seeded ``seed + i``); the other
    envs step along and their data are dropped. VecEnvs reset finished envs automatically, so an
    env's first ``done`` ends its episode here."""
    venv.seed(seed)
    obs = venv.reset()
    totals = np.zeros(venv.num_envs, dtype=np.float64)
    steps = np.zeros(venv.num_envs, dtype=np.int64)
    running = np.arange(venv.num_envs) < n_active
    while running.any():
        obs, rewards, dones, _ = venv.step(act(obs))
        totals += np.where(running, rewards, 0.0)
        steps += running
        running &= ~dones.astype(bool)
        if max_steps and steps.max() >= max_steps:
            break
    return [float(r) for r in totals[:n_active]], [int(n) for n in steps[:n_active]]
