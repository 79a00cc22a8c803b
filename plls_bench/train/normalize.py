"""Observation and reward normalisation for PPO through stable-baselines3's ``VecNormalize``
(rl-baselines3-zoo's ``normalize`` recipe key). Off unless ``algo.ppo.normalize_obs`` or
``algo.ppo.normalize_reward`` is set; the paper says nothing about normalisation.

The training env updates running statistics; test episodes, filmstrips and ``load_trained`` see
the same observation statistics frozen (no updates, no reward scaling, so returns stay raw).
Statistics are saved with every checkpoint as JSON (exact float64 round trip) and restored on
resume, like the zoo's ``vecnormalize.pkl`` beside the model.
"""
from __future__ import annotations

import copy
import json
from collections.abc import Callable
from typing import Any

import numpy as np
from stable_baselines3.common.running_mean_std import RunningMeanStd
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

from plls_bench.config import PPOConfig

ObsMap = Callable[[np.ndarray], np.ndarray]


def wrap_training(venv: VecEnv, ppo: PPOConfig) -> VecEnv:
    """``venv`` in a learning ``VecNormalize`` when normalisation is on, else ``venv`` itself."""
    if not ppo.normalized:
        return venv
    return VecNormalize(venv, training=True, norm_obs=ppo.normalize_obs, norm_reward=ppo.normalize_reward,
                        gamma=ppo.gamma)


def wrap_frozen(venv: VecEnv, ppo: PPOConfig) -> VecEnv:
    """``venv`` for test episodes: observations normalised with frozen statistics (copied in by
    :func:`sync`), rewards raw."""
    if not ppo.normalized:
        return venv
    return VecNormalize(venv, training=False, norm_obs=ppo.normalize_obs, norm_reward=False, gamma=ppo.gamma)


def sync(source: VecEnv, target: VecEnv) -> None:
    """Copy the training env's observation statistics into a frozen test env (no-op when off)."""
    if isinstance(source, VecNormalize) and isinstance(target, VecNormalize):
        target.obs_rms = copy.deepcopy(source.obs_rms)


def _rms_to_dict(rms: RunningMeanStd) -> dict[str, Any]:
    return {"mean": np.asarray(rms.mean).tolist(), "var": np.asarray(rms.var).tolist(), "count": float(rms.count)}


def _rms_from_dict(data: dict[str, Any]) -> RunningMeanStd:
    mean = np.asarray(data["mean"], dtype=np.float64)
    rms = RunningMeanStd(shape=mean.shape)
    rms.mean, rms.var, rms.count = mean, np.asarray(data["var"], dtype=np.float64), float(data["count"])
    return rms


def state_json(venv: VecEnv) -> bytes | None:
    """The running statistics of a training ``VecNormalize`` as JSON bytes; None when off."""
    if not isinstance(venv, VecNormalize):
        return None
    state = {"obs_rms": _rms_to_dict(venv.obs_rms), "ret_rms": _rms_to_dict(venv.ret_rms),
             "norm_obs": venv.norm_obs, "norm_reward": venv.norm_reward, "clip_obs": venv.clip_obs,
             "clip_reward": venv.clip_reward, "gamma": venv.gamma, "epsilon": venv.epsilon}
    return (json.dumps(state, indent=1) + "\n").encode()


def restore(venv: VecEnv, data: bytes) -> None:
    """Put saved statistics back into ``venv`` (a ``VecNormalize``)."""
    if not isinstance(venv, VecNormalize):
        raise ValueError("checkpoint has VecNormalize statistics but the env is not normalised")
    state = json.loads(data)
    venv.obs_rms, venv.ret_rms = _rms_from_dict(state["obs_rms"]), _rms_from_dict(state["ret_rms"])


def frozen_obs_map(data: bytes | None) -> ObsMap:
    """A function normalising observations with saved statistics, frozen (identity when none):
    what a trained policy's observations go through outside its training env."""
    if data is None:
        return lambda obs: obs
    state = json.loads(data)
    if not state["norm_obs"]:
        return lambda obs: obs
    rms, clip, eps = _rms_from_dict(state["obs_rms"]), float(state["clip_obs"]), float(state["epsilon"])

    def normalise(obs: np.ndarray) -> np.ndarray:
        scaled = (np.asarray(obs, dtype=np.float64) - rms.mean) / np.sqrt(rms.var + eps)
        return np.clip(scaled, -clip, clip).astype(np.float32)

    return normalise
