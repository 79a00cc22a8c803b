"""Env factories for the paper's three tasks, keyed by ``env.name``.

Pixel observations are channel-first uint8 everywhere in the suite: CarRacing ``(3, 96, 96)``,
Cheetah ``(3 * frame_stack, 84, 84)`` (as the DBC reference). The networks divide by 255 (SB3's
image convention for PPO's policy, V_s's batches, DBC's encoder), so they compute on the paper's
"three floating point values between 0 and 1" (Sec. 5.2) while rollouts and data keep uint8.

Layer ``tasks`` of tests/test_imports.py: imports only from itself and the layers below it
(``core`` up to ``run dirs``); no layer below imports it.
"""
from __future__ import annotations

from collections.abc import Callable

import gymnasium as gym

from plls_bench.config import EnvConfig


def _mountaincar(cfg: EnvConfig, for_data: bool, render_mode: str | None) -> gym.Env:
    return gym.make(cfg.gym_id, max_episode_steps=cfg.max_episode_steps, render_mode=render_mode)


def _carracing(cfg: EnvConfig, for_data: bool, render_mode: str | None) -> gym.Env:
    from plls_bench.envs.carracing import ChannelsFirst

    env = gym.make(cfg.gym_id, continuous=True, max_episode_steps=cfg.max_episode_steps,
                   render_mode=render_mode)
    return ChannelsFirst(env)


def _cheetah(cfg: EnvConfig, for_data: bool, render_mode: str | None) -> gym.Env:
    from plls_bench.envs.dmc import DMCEnv

    pixels = cfg.data_pixels if for_data else cfg.pixels
    return DMCEnv(cfg.gym_id, pixels=pixels, image_size=cfg.image_size, camera_id=cfg.camera_id,
                  action_repeat=cfg.action_repeat, frame_stack=cfg.frame_stack,
                  max_episode_steps=cfg.max_episode_steps, render_mode=render_mode, visuals=cfg.visuals)


ENV_FACTORIES: dict[str, Callable[[EnvConfig, bool, str | None], gym.Env]] = {
    "mountaincar": _mountaincar,
    "carracing": _carracing,
    "cheetah": _cheetah,
}


def make_env(cfg: EnvConfig, *, for_data: bool = False, render_mode: str | None = None) -> gym.Env:
    """One env of task ``cfg.name``. ``for_data``: the observation layout stored in random-policy
    datasets (uint8 pixels; Cheetah's proprioceptive state unless ``env.data_pixels``).
    Always the gymnasium engine, whatever ``env.backend``: single envs serve spaces and
    filmstrips (rendering), which envpool does not offer; vector envs follow the backend."""
    return ENV_FACTORIES[cfg.name](cfg, for_data, render_mode)


def make_vec_env(cfg: EnvConfig, n_envs: int, seed: int, *, subproc: bool = False):
    """A stable-baselines3 VecEnv of ``n_envs`` copies; env i's first reset uses ``seed + i``.
    ``env.backend=envpool``: one C++ pool (``subproc`` does not apply; it has threads of its own)."""
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    if cfg.backend == "envpool":
        from plls_bench.envs.envpool_backend import ENVPOOL_TASKS, EnvpoolVecEnv

        return EnvpoolVecEnv(ENVPOOL_TASKS[cfg.gym_id], n_envs, cfg.max_episode_steps,
                             cfg.backend_threads, seed=seed)
    factories = [lambda: make_env(cfg) for _ in range(n_envs)]
    venv = SubprocVecEnv(factories, start_method="forkserver") if subproc else DummyVecEnv(factories)
    venv.seed(seed)
    return venv
