"""Building blocks of the PPO runner: vector envs behind the PL-LS wrappers, the SB3 model, its
parameter accounting, and loading a trained policy back from a run directory."""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.save_util import load_from_zip_file
from stable_baselines3.common.vec_env import VecEnv, VecMonitor
from torch import nn

from plls_bench.config import Config
from plls_bench.core.seeding import quiet_rng
from plls_bench.envs import make_vec_env
from plls_bench.repr.latent_wrappers import latent_modules, wrap_latent
from plls_bench.repr.store import Representations, load_representations
from plls_bench.rundirs.composition import recorded_config
from plls_bench.rundirs.devices import resolve_device
from plls_bench.train.checkpoint import latest, missing_checkpoint, normalization
from plls_bench.train.networks import ChannelsLastPolicy, policy_kwargs
from plls_bench.train.normalize import ObsMap, frozen_obs_map
from plls_bench.train.trained_policy import TrainedPolicy


def build_vec_env(cfg: Config, n_envs: int, seed: int, reprs: Representations | None = None) -> VecEnv:
    """``n_envs`` copies of the task, episode statistics recorded on the raw env (VecMonitor),
    then the V_s / V_a of ``reprs`` (``wrap_latent``; None only for a config that uses neither).
    Env i's first reset uses ``seed + i``."""
    assert cfg.algo.ppo is not None
    reprs = (reprs or Representations()).check(cfg)  # before any env process starts
    venv = make_vec_env(cfg.env, n_envs, seed, subproc=cfg.algo.ppo.vec_env == "subproc" and n_envs > 1)
    return wrap_latent(VecMonitor(venv), reprs)


def new_model(cfg: Config, venv: VecEnv) -> PPO:
    """An untrained SB3 PPO with Table 1 / Table 2 settings and the paper's shared network."""
    ppo = cfg.algo.ppo
    assert ppo is not None
    return PPO(ChannelsLastPolicy, venv, learning_rate=ppo.learning_rate, n_steps=ppo.n_steps,
               batch_size=ppo.batch_size, n_epochs=ppo.n_epochs, gamma=ppo.gamma,
               gae_lambda=ppo.gae_lambda, clip_range=ppo.clip_range, ent_coef=ppo.ent_coef,
               vf_coef=ppo.vf_coef, max_grad_norm=ppo.max_grad_norm,
               policy_kwargs=policy_kwargs(ppo, cfg.precision),
               use_sde=ppo.use_sde, sde_sample_freq=ppo.sde_sample_freq if ppo.sde_sample_freq else -1,
               device=resolve_device(cfg.device), verbose=0)


def load_model(zip_path: Path, device: torch.device, venv: VecEnv | None = None) -> PPO:
    """A checkpointed PPO, on ``venv`` (to train on) or without an env (to act).

    Policies saved while CarRacing frames were float32 in [0, 1] load onto today's uint8 frames:
    SB3 divides a uint8 image Box by 255 itself, so the same weights see the same values; only
    the observation space the checkpoint records is read as the uint8 image Box."""
    data, _, _ = load_from_zip_file(zip_path, device="cpu", load_data=True)
    space = _uint8_pixels(data["observation_space"])
    with quiet_rng(device):  # PPO.load builds a policy (random init) before loading its weights
        return PPO.load(zip_path, env=venv, device=device, custom_objects={"observation_space": space})


def _uint8_pixels(space: gym.spaces.Space) -> gym.spaces.Space:
    """A float32 [0, 1] image Box as SB3's uint8 image Box; any other space unchanged."""
    if (isinstance(space, gym.spaces.Box) and len(space.shape) == 3 and space.dtype == np.float32
            and np.all(space.low == 0.0) and np.all(space.high == 1.0)):
        return gym.spaces.Box(0, 255, space.shape, np.uint8)
    return space


def accounting(model: PPO, venv: VecEnv) -> tuple[dict[str, nn.Module], dict[str, torch.Tensor]]:
    """Every module the method runs (the policy, trained; V_s's encoder / V_a's decoder, frozen)
    and an example input batch for each, for ``params.json`` and ``architecture.json``."""
    modules: dict[str, nn.Module] = {"policy": model.policy, **latent_modules(venv)}
    shapes = {"policy": model.observation_space.shape,
              "V_s.encoder": venv.unwrapped.observation_space.shape,  # the raw image
              "V_a.decoder": venv.action_space.shape}                 # the policy's e
    return modules, {name: torch.zeros(1, *shapes[name]) for name in modules}


@dataclass(frozen=True)
class Trained:
    """A run's typed config, its last checkpointed PPO, the frozen observation normalisation
    it was trained with (identity unless ``algo.ppo.normalize_obs``) and its V_s / V_a."""

    cfg: Config
    model: PPO
    normalize_obs: ObsMap
    reprs: Representations

    def act(self, obs: np.ndarray, deterministic: bool = True) -> np.ndarray:
        """Actions for ``build_vec_env`` observations (normalised here, frozen, as in evaluation)."""
        return self.model.predict(self.normalize_obs(obs), deterministic=deterministic)[0]


def load_trained(run_dir: str | Path, device: str = "auto") -> Trained:
    """The run's last checkpointed policy (the final one once the run is ``done``) and its V_s /
    V_a, on ``device`` (``auto``: the GPU when present). It acts on ``build_vec_env(cfg, n, seed,
    trained.reprs)`` observations (latent z with V_s) through :meth:`Trained.act`, which applies the
    saved VecNormalize statistics frozen; its actions are what that env's ``step`` takes (latent e
    with V_a). Never trains: a missing V_s / V_a artifact raises ``MissingArtifact``."""
    cfg = recorded_config(run_dir)
    found = latest(Path(run_dir))
    if found is None:
        raise missing_checkpoint(run_dir)
    model = load_model(found[0], resolve_device(device))
    reprs = load_representations(replace(cfg, device=device))  # beside the policy, not on the recorded device
    return Trained(cfg, model, frozen_obs_map(normalization(Path(run_dir))), reprs)


def trained_policy(run_dir: Path, device: str) -> TrainedPolicy:
    """The run's policy as :func:`load_trained` gives it, deterministic, named by its checkpoint."""
    trained = load_trained(run_dir, device)
    found = latest(run_dir)
    assert found is not None  # load_trained raised otherwise
    # V_s / V_a join the policy on the device it was loaded to, not the recorded one
    return TrainedPolicy(replace(trained.cfg, device=device), trained.act, found[0].name, trained.reprs)


def sb3_metrics(values: dict[str, Any]) -> dict[str, float]:
    """SB3's per-update logger values, renamed to the suite's prefixed metric names."""
    names = {"train/policy_gradient_loss": "loss/policy", "train/value_loss": "loss/value",
             "train/entropy_loss": "loss/entropy", "train/loss": "loss/total",
             "train/approx_kl": "train/approx_kl", "train/clip_fraction": "train/clip_fraction",
             "train/explained_variance": "train/explained_variance", "train/std": "train/action_std",
             "train/learning_rate": "train/learning_rate", "train/clip_range": "train/clip_range",
             "train/n_updates": "train/n_updates"}
    return {new: float(values[old]) for old, new in names.items() if old in values}
