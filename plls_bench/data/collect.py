"""Random-policy data (Algorithm 1, line 1): vectorised collection of (s, a, r, s').

Episode j is reset with its own seed and draws its actions from its own stream, so the data do
not depend on how many envs run in parallel. Envs run in waves of ``env.data_num_envs`` episodes;
an env whose episode has ended idles (its steps are discarded) until the wave is over.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import gymnasium as gym
import numpy as np
from gymnasium.vector import AsyncVectorEnv, AutoresetMode, SyncVectorEnv
from scipy import special
from tqdm.auto import tqdm

from plls_bench.config import EnvConfig
from plls_bench.core.progress_bars import progress_bar
from plls_bench.core.seeding import episode_seeds
from plls_bench.envs import make_env


@dataclass
class _Episode:
    observations: list[np.ndarray]
    actions: list[np.ndarray] = field(default_factory=list)
    rewards: list[float] = field(default_factory=list)
    terminated: list[bool] = field(default_factory=list)
    truncated: list[bool] = field(default_factory=list)


def action_stream(seed: int, steps: int, space: gym.spaces.Box, policy: str = "uniform",
                  correlation: float = 0.0) -> np.ndarray:
    """``(steps, action_dim)`` random-policy actions in the action box.

    ``uniform``: independent draws, uniform in the box. ``correlated``: every action dimension
    is still exactly uniform in its interval at every step, but consecutive actions are
    correlated: a stationary AR(1) Gaussian process x_t = rho x_{t-1} + sqrt(1 - rho^2) eps_t
    is mapped through the normal CDF onto the interval (rho = ``correlation``).
    """
    rng = np.random.default_rng([seed, 1])  # distinct from the env's reset stream
    if policy == "uniform":
        return rng.uniform(space.low, space.high, size=(steps, *space.shape)).astype(np.float32)
    noise = rng.standard_normal((steps, *space.shape))
    latent = np.empty_like(noise)
    latent[0] = noise[0]
    scale = np.sqrt(1.0 - correlation**2)
    for t in range(1, steps):
        latent[t] = correlation * latent[t - 1] + scale * noise[t]
    return (space.low + special.ndtr(latent) * (space.high - space.low)).astype(np.float32)


def _vector_env(cfg: EnvConfig, n_envs: int) -> gym.vector.VectorEnv:
    if cfg.backend == "envpool":
        from plls_bench.envs.envpool_backend import ENVPOOL_TASKS, EnvpoolDataEnvs

        return EnvpoolDataEnvs(ENVPOOL_TASKS[cfg.gym_id], n_envs, cfg.max_episode_steps, cfg.backend_threads)
    factory = partial(make_env, cfg, for_data=True)
    vector_cls = AsyncVectorEnv if cfg.data_async and n_envs > 1 else SyncVectorEnv
    return vector_cls([factory] * n_envs, autoreset_mode=AutoresetMode.DISABLED)


def _run_wave(envs: gym.vector.VectorEnv, seeds: list[int], max_steps: int, bar: tqdm,
              policy: str, correlation: float) -> list[_Episode]:
    """One episode per seed, in parallel; envs beyond ``len(seeds)`` idle."""
    n_envs = envs.num_envs
    single_space = envs.single_action_space
    streams = [action_stream(s, max_steps, single_space, policy, correlation) for s in seeds]
    reset_seeds = seeds + [seeds[-1]] * (n_envs - len(seeds))  # idle envs: any seed, data dropped
    obs, _ = envs.reset(seed=reset_seeds)
    episodes = [_Episode(observations=[obs[i]]) for i in range(len(seeds))]
    active = np.arange(n_envs) < len(seeds)
    idle_action = np.zeros(single_space.shape, dtype=np.float32)
    for t in range(max_steps):
        actions = np.stack([streams[i][t] if active[i] else idle_action for i in range(n_envs)])
        obs, rewards, terminated, truncated, _ = envs.step(actions)
        bar.update(int(active.sum()))
        for i in np.flatnonzero(active):
            ep = episodes[i]
            cut = t + 1 == max_steps  # the data budget ends the episode: a truncation
            ep.actions.append(actions[i])
            ep.rewards.append(float(rewards[i]))
            ep.terminated.append(bool(terminated[i]))
            ep.truncated.append(bool(truncated[i]) or (cut and not terminated[i]))
            ep.observations.append(obs[i])
            active[i] = not (terminated[i] or truncated[i])
        if not active.any():
            break
    return episodes


def _to_arrays(episodes: list[_Episode]) -> dict[str, np.ndarray]:
    """Flat arrays: transitions i of all episodes, observations with each episode's final one.

    ``observations[obs_index[i]]`` is s_i and ``observations[obs_index[i] + 1]`` is s'_i.
    """
    obs_index, offset = [], 0
    for ep in episodes:
        obs_index.append(offset + np.arange(len(ep.actions)))
        offset += len(ep.observations)
    return {
        "observations": np.stack([o for ep in episodes for o in ep.observations]),
        "actions": np.stack([a for ep in episodes for a in ep.actions]).astype(np.float32),
        "rewards": np.asarray([r for ep in episodes for r in ep.rewards], dtype=np.float32),
        "terminated": np.asarray([d for ep in episodes for d in ep.terminated], dtype=bool),
        "truncated": np.asarray([d for ep in episodes for d in ep.truncated], dtype=bool),
        "episode": np.concatenate([np.full(len(ep.actions), j, dtype=np.int32)
                                   for j, ep in enumerate(episodes)]),
        "obs_index": np.concatenate(obs_index).astype(np.int64),
    }


def collect_random_policy(cfg: EnvConfig, episodes: int, max_steps: int, seed: int,
                          progress: bool = True) -> dict[str, np.ndarray]:
    """Run the uniform random policy for ``episodes`` episodes of at most ``max_steps`` steps."""
    seeds = episode_seeds(seed, episodes)
    n_envs = min(cfg.data_num_envs, episodes)
    collected: list[_Episode] = []
    envs = _vector_env(cfg, n_envs)
    try:
        with progress_bar(total=episodes * max_steps, desc=f"random-policy data ({cfg.name})",
                  unit="step", disable=not progress) as bar:
            for start in range(0, episodes, n_envs):
                collected += _run_wave(envs, seeds[start:start + n_envs], max_steps, bar,
                                       cfg.data_policy, cfg.data_policy_correlation)
    finally:
        envs.close()
    return _to_arrays(collected)
