"""The DBC agent: SAC on a bisimulation-shaped latent (reference: agent/bisim_agent.py).

One :meth:`DBCAgent.update` per agent step, in the reference's order: critic (which also trains
the critic's encoder), then the encoder with the bisimulation, transition and reward losses, then
(every ``actor_update_freq`` steps) actor and temperature, then (every
``critic_target_update_freq`` steps) the soft target update. The actor shares the critic's conv
trunk but never trains it; its own Linear + LayerNorm head is trained by the actor loss.
With ``encoder=critic`` (pixel SAC, the reference's agent/baseline_agent.py with ``--decoder_type
identity``) the same encoder is trained by the critic alone: no representation step, no models.
"""
from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

from baselines.dbc.bisim import bisimulation_loss, latent_batch_std, reward_loss, transition_loss
from baselines.dbc.encoder import ConvStack, Encoder, IdentityEncoder, make_trunk, plain_conv_stack, weight_init
from baselines.dbc.hyperparameters import Hyperparameters
from baselines.dbc.models import Actor, Critic, TransitionModel, reward_decoder


@dataclass
class Batch:
    """A sampled minibatch: obs/next_obs ``(B, *O)`` (uint8 pixels or float vectors), action
    ``(B, A)`` in [-1, 1], reward and not_done ``(B, 1)`` float32."""

    obs: torch.Tensor
    action: torch.Tensor
    reward: torch.Tensor
    next_obs: torch.Tensor
    not_done: torch.Tensor


def soft_update(net: nn.Module, target: nn.Module, tau: float) -> None:
    with torch.no_grad():
        for param, target_param in zip(net.parameters(), target.parameters()):
            target_param.lerp_(param, tau)


class DBCAgent:
    """Actor, twin critic (+ target), transition model and reward decoder (``encoder=bisim``), with
    their optimisers.
    ``conv_stack`` builds what runs the pixel encoder's conv layers (default: a plain ``Sequential``;
    the suite passes its channels_last trunk in the run's precision)."""

    def __init__(self, obs_shape: tuple[int, ...], action_dim: int, cfg: Hyperparameters,
                 device: torch.device | str = "cpu", conv_stack: ConvStack = plain_conv_stack) -> None:
        self.cfg, self.device = cfg, torch.device(device)
        # bisim: DBC's learned encoder and its losses; critic: the same encoder trained by the critic
        # alone (pixel SAC, the reference's --agent baseline); identity: state SAC (no encoder)
        self.learns_representation = cfg.encoder == "bisim"
        self.has_encoder = cfg.encoder != "identity"
        encoder: Callable[[], nn.Module] = partial(IdentityEncoder, obs_shape)
        if self.has_encoder:
            trunk = make_trunk(obs_shape, cfg.num_layers, cfg.num_filters, cfg.hidden_dim, conv_stack)
            # the actor shares the critic's trunk (the reference ties the conv weights)
            encoder = partial(Encoder, trunk, cfg.encoder_feature_dim)
        self.critic = Critic(encoder(), action_dim, cfg.hidden_dim)
        self.actor = Actor(encoder(), action_dim, cfg.hidden_dim, cfg.actor_log_std_min, cfg.actor_log_std_max)
        self.transition: TransitionModel | None = None
        self.reward_decoder: nn.Module | None = None
        if self.learns_representation:
            self.transition = TransitionModel(cfg.encoder_feature_dim, action_dim, cfg.model_hidden_dim,
                                              cfg.transition_model == "probabilistic", cfg.sigma_min, cfg.sigma_max)
            self.reward_decoder = reward_decoder(cfg.encoder_feature_dim, cfg.model_hidden_dim)
        for module in (self.critic, self.actor):  # the reference leaves the models at torch's init
            module.apply(weight_init)
        self.critic_target = copy.deepcopy(self.critic).requires_grad_(False)  # Polyak-averaged only
        for module in self.modules().values():
            module.to(self.device)
        self.log_alpha = torch.tensor(math.log(cfg.init_temperature), device=self.device, requires_grad=True)
        self.target_entropy = -float(action_dim)  # SAC's heuristic -|A|, as the reference
        self.optimizers = self._make_optimizers()

    def _make_optimizers(self) -> dict[str, torch.optim.Optimizer]:
        cfg, actor = self.cfg, self.actor
        actor_params = [*actor.trunk.parameters(), *actor.encoder.fc.parameters(), *actor.encoder.ln.parameters()]
        optimizers = {
            "actor": torch.optim.Adam(actor_params, lr=cfg.actor_lr, betas=(cfg.actor_beta, 0.999)),
            "critic": torch.optim.Adam(self.critic.parameters(), lr=cfg.critic_lr, betas=(cfg.critic_beta, 0.999)),
            "alpha": torch.optim.Adam([self.log_alpha], lr=cfg.alpha_lr, betas=(cfg.alpha_beta, 0.999)),
        }
        if self.transition is not None and self.reward_decoder is not None:
            model_params = [*self.transition.parameters(), *self.reward_decoder.parameters()]
            optimizers["encoder"] = torch.optim.Adam(self.critic.encoder.parameters(), lr=cfg.encoder_lr)
            optimizers["decoder"] = torch.optim.Adam(model_params, lr=cfg.decoder_lr,
                                                     weight_decay=cfg.decoder_weight_lambda)
        return optimizers

    def modules(self) -> dict[str, nn.Module]:
        """The agent's networks by checkpoint name (no models without a learned representation)."""
        modules = {"actor": self.actor, "critic": self.critic, "critic_target": self.critic_target}
        if self.transition is not None and self.reward_decoder is not None:
            modules.update(transition_model=self.transition, reward_decoder=self.reward_decoder)
        return modules

    @property
    def alpha(self) -> torch.Tensor:
        return self.log_alpha.exp()

    # ------------------------------------------------------------------ acting
    @torch.inference_mode()
    def act(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        """Actions ``(N, A)`` in [-1, 1] for observations ``(N, *O)``: ``tanh(mu)`` or a sample."""
        features = self.critic.encoder.features(torch.as_tensor(obs, device=self.device))
        mu, pi, _, _ = self.actor(features, sample=not deterministic)
        return (mu if deterministic else pi).cpu().numpy()

    # ------------------------------------------------------------------ learning
    def update(self, batch: Batch, step: int) -> dict[str, float]:
        """One update at agent step ``step``; returns scalar metrics (``loss/...``, ``train/...``).

        As in the reference, the actor and target schedules key on the agent step, so the burst of
        ``init_steps`` updates at the first learning step all update the actor and targets."""
        metrics = {"loss/critic": self.update_critic(batch)}
        if self.learns_representation:
            metrics.update(self.update_representation(batch))
        if step % self.cfg.actor_update_freq == 0:
            metrics.update(self.update_actor_and_alpha(batch.obs))
        if step % self.cfg.critic_target_update_freq == 0:
            soft_update(self.critic.q1, self.critic_target.q1, self.cfg.critic_tau)
            soft_update(self.critic.q2, self.critic_target.q2, self.cfg.critic_tau)
            soft_update(self.critic.encoder, self.critic_target.encoder, self.cfg.encoder_tau)
        metrics["train/batch_reward"] = float(batch.reward.mean())
        return metrics

    def update_critic(self, batch: Batch) -> float:
        with torch.no_grad():
            _, next_action, next_log_pi, _ = self.actor(self.critic.encoder.features(batch.next_obs))
            target_q1, target_q2 = self.critic_target(self.critic_target.encoder.features(batch.next_obs), next_action)
            target_v = torch.min(target_q1, target_q2) - self.alpha * next_log_pi
            target_q = batch.reward + batch.not_done * self.cfg.discount * target_v
        q1, q2 = self.critic(self.critic.encoder.features(batch.obs), batch.action)
        loss = F.mse_loss(q1, target_q) + F.mse_loss(q2, target_q)
        self._step("critic", loss)
        return loss.item()

    def update_representation(self, batch: Batch) -> dict[str, float]:
        """Encoder, transition model and reward decoder: ``bisim_coef * L_bisim + L_trans + L_reward``."""
        assert self.transition is not None and self.reward_decoder is not None
        z = self.critic.encoder(batch.obs)
        with torch.no_grad():
            next_z = self.critic.encoder(batch.next_obs)
        l_trans = transition_loss(z, batch.action, next_z, self.transition)
        l_reward = reward_loss(z, batch.action, batch.reward, self.transition, self.reward_decoder)
        l_bisim = bisimulation_loss(z, batch.action, batch.reward, self.transition, self.cfg.discount)
        total = self.cfg.bisim_coef * l_bisim + l_trans + l_reward
        self._step(("encoder", "decoder"), total)
        return {"loss/encoder_bisim": l_bisim.item(), "loss/transition": l_trans.item(),
                "loss/reward": l_reward.item(), "train/latent_batch_std": latent_batch_std(z)}

    def update_actor_and_alpha(self, obs: torch.Tensor) -> dict[str, float]:
        with torch.no_grad():  # the actor never trains the shared trunk (detach_encoder in the reference)
            features = self.critic.encoder.features(obs)
        _, pi, log_pi, log_std = self.actor(features, detach_trunk=True)
        q1, q2 = self.critic(features, pi, detach_trunk=True)
        actor_loss = (self.alpha.detach() * log_pi - torch.min(q1, q2)).mean()
        self._step("actor", actor_loss)
        alpha_loss = (self.alpha * (-log_pi - self.target_entropy).detach()).mean()
        self._step("alpha", alpha_loss)
        entropy = 0.5 * log_std.shape[1] * (1.0 + math.log(2 * math.pi)) + log_std.sum(dim=-1)
        metrics = {"loss/actor": actor_loss.item(), "loss/alpha": alpha_loss.item(),
                   "train/alpha": self.alpha.item(), "train/entropy": entropy.mean().item()}
        if self.has_encoder and not self.learns_representation:  # pixel SAC: DBC logs its own spread
            with torch.no_grad():  # the critic's latent of this batch, as DBC's after its critic step
                metrics["train/latent_batch_std"] = latent_batch_std(self.critic.encoder.head(features))
        return metrics

    def _step(self, names: str | tuple[str, ...], loss: torch.Tensor) -> None:
        """Zero the named optimisers' gradients, backpropagate ``loss`` and step them."""
        names = (names,) if isinstance(names, str) else names
        for name in names:
            self.optimizers[name].zero_grad(set_to_none=True)
        loss.backward()
        for name in names:
            self.optimizers[name].step()

    # ------------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict[str, Any]:
        return {"modules": {name: m.state_dict() for name, m in self.modules().items()},
                "log_alpha": self.log_alpha.detach().clone(),
                "optimizers": {name: opt.state_dict() for name, opt in self.optimizers.items()}}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        for name, module in self.modules().items():
            module.load_state_dict(state["modules"][name])
        with torch.no_grad():
            self.log_alpha.copy_(state["log_alpha"])
        for name, opt in self.optimizers.items():
            opt.load_state_dict(state["optimizers"][name])
