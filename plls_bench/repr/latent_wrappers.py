"""PL-LS as vector-env wrappers: the policy sees z = V_s.encoder(s) and emits e = V_a's latent.

Both wrappers make exactly one batched forward pass per vector step for all ``n_envs`` envs,
under ``torch.inference_mode()``, with frozen models. Any stable-baselines3 learner then trains
the small policy on an ordinary env: Box(N_z) observations, Box(+-bound, N_e) actions.
"""
from __future__ import annotations

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn
from torch import nn

from plls_bench.repr.models import ActionVAE, StateVAE
from plls_bench.repr.pixel_trunk import pixels_to_unit
from plls_bench.repr.store import Representations


def _device(module: nn.Module) -> torch.device:
    return next(module.parameters()).device


class LatentObservation(VecEnvWrapper):
    """Observations ``(n, 3, H, W)`` (uint8, or float in [0, 1]) -> V_s encoder means ``(n, N_z)``.

    uint8 frames become float32 exactly as V_s's training batches do (:func:`pixels_to_unit`), so
    V_s sees the frames it was trained on; its encoder runs in the precision it was built with.

    ``terminal_observation`` entries of the step's infos (envs that just finished; PPO bootstraps
    truncated episodes from them) are encoded in the same forward pass as the observations.
    """

    def __init__(self, venv: VecEnv, state_vae: StateVAE) -> None:
        space = venv.observation_space
        if not isinstance(space, spaces.Box) or tuple(space.shape) != tuple(state_vae.image_shape):
            raise ValueError(f"LatentObservation needs Box observations of shape {state_vae.image_shape} "
                             f"for V_s, got {space}")
        self.state_vae = state_vae
        latent = spaces.Box(-np.inf, np.inf, shape=(state_vae.latent_dim,), dtype=np.float32)
        super().__init__(venv, observation_space=latent)

    def encode(self, obs: np.ndarray) -> np.ndarray:
        """``(k, 3, H, W)`` -> ``(k, N_z)`` float32 posterior means, one forward pass."""
        with torch.inference_mode():
            mu, _ = self.state_vae.encode(pixels_to_unit(torch.as_tensor(obs, device=_device(self.state_vae))))
        return mu.cpu().numpy().astype(np.float32, copy=False)

    def reset(self) -> VecEnvObs:
        return self.encode(np.asarray(self.venv.reset()))

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, dones, infos = self.venv.step_wait()
        done = [i for i, info in enumerate(infos) if "terminal_observation" in info]
        batch = np.concatenate([np.asarray(obs), *(infos[i]["terminal_observation"][None] for i in done)])
        z = self.encode(batch)
        for row, i in enumerate(done, start=len(obs)):
            infos[i]["terminal_observation"] = z[row]
        return z[:len(obs)], rewards, dones, infos


class LatentAction(VecEnvWrapper):
    """Latent actions e ``(n, N_e)`` -> clip to +-``bound`` -> V_a decoder mean -> clip to the env's
    action box. ``last_env_actions`` keeps the ``(n, A)`` actions the envs last received."""

    def __init__(self, venv: VecEnv, action_vae: ActionVAE, bound: float) -> None:
        space = venv.action_space
        if not isinstance(space, spaces.Box) or space.shape != (action_vae.action_dim,):
            raise ValueError(f"LatentAction needs a Box action space of shape ({action_vae.action_dim},) "
                             f"for V_a, got {space}")
        self.action_vae, self.bound = action_vae, float(bound)
        self._low, self._high = space.low.astype(np.float32), space.high.astype(np.float32)
        self.last_env_actions: np.ndarray | None = None
        latent = spaces.Box(-self.bound, self.bound, shape=(action_vae.latent_dim,), dtype=np.float32)
        super().__init__(venv, action_space=latent)

    def decode(self, latent: np.ndarray) -> np.ndarray:
        """``(k, N_e)`` -> ``(k, A)`` float32 env actions, one forward pass."""
        e = np.clip(np.asarray(latent, dtype=np.float32), -self.bound, self.bound)
        with torch.inference_mode():
            a_hat = self.action_vae.decode(torch.as_tensor(e, device=_device(self.action_vae)))
        return np.clip(a_hat.cpu().numpy().astype(np.float32, copy=False), self._low, self._high)

    def step_async(self, actions: np.ndarray) -> None:
        self.last_env_actions = self.decode(np.reshape(actions, (self.num_envs, -1)))
        self.venv.step_async(self.last_env_actions)

    def reset(self) -> VecEnvObs:
        return self.venv.reset()

    def step_wait(self) -> VecEnvStepReturn:
        return self.venv.step_wait()


def wrap_latent(venv: VecEnv, reprs: Representations) -> VecEnv:
    """Apply the loaded V_s and V_a of ``reprs`` to ``venv`` (each only when present); with
    neither the same ``venv`` object comes back untouched. Builds and loads nothing: the runner's
    setup hands the models down (:func:`plls_bench.repr.store.ensure_representations`)."""
    if reprs.state_vae is not None:
        venv = LatentObservation(venv, reprs.state_vae)
    if reprs.action_vae is not None:
        venv = LatentAction(venv, reprs.action_vae, reprs.action_bound)
    return venv


def latent_modules(venv: VecEnv) -> dict[str, nn.Module]:
    """The frozen modules the latent wrappers around ``venv`` run, by name (``V_s.encoder``,
    ``V_a.decoder``), for parameter accounting (Table 3) and architecture summaries (Fig. 17)."""
    found: dict[str, nn.Module] = {}
    while isinstance(venv, VecEnvWrapper):
        if isinstance(venv, LatentObservation):
            found["V_s.encoder"] = venv.state_vae.encoder
        if isinstance(venv, LatentAction):
            found["V_a.decoder"] = venv.action_vae.decoder
        venv = venv.venv
    return found
