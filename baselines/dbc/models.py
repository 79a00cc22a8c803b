"""SAC actor and twin critic, latent transition model and reward decoder of DBC.

Shapes: ``z`` latent ``(B, Z)``, ``a`` action ``(B, A)`` in [-1, 1]. Architectures follow the
reference (deep_bisim4control: sac_ae.py, transition_model.py, agent/bisim_agent.py).
"""
from __future__ import annotations

import math

import torch
import torch.nn as nn

from baselines.dbc.encoder import Encoder, IdentityEncoder


def mlp(in_dim: int, hidden_dim: int, out_dim: int) -> nn.Sequential:
    """Two hidden ReLU layers, as the reference's actor trunk and Q-functions."""
    return nn.Sequential(nn.Linear(in_dim, hidden_dim), nn.ReLU(),
                         nn.Linear(hidden_dim, hidden_dim), nn.ReLU(),
                         nn.Linear(hidden_dim, out_dim))


class Actor(nn.Module):
    """tanh-squashed diagonal Gaussian policy on the encoder's latent."""

    def __init__(self, encoder: Encoder | IdentityEncoder, action_dim: int, hidden_dim: int,
                 log_std_min: float, log_std_max: float) -> None:
        super().__init__()
        self.encoder = encoder
        self.trunk = mlp(encoder.feature_dim, hidden_dim, 2 * action_dim)
        self.log_std_min, self.log_std_max = log_std_min, log_std_max

    def forward(self, features: torch.Tensor, *, detach_trunk: bool = False,
                sample: bool = True) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor | None, torch.Tensor]:
        """From trunk features ``(B, F)``: ``tanh(mu)``, a squashed sample, its log-prob ``(B, 1)``
        and ``log_std`` ``(B, A)``; sample and log-prob are None when ``sample`` is False."""
        mu, log_std = self.trunk(self.encoder.head(features, detach_trunk)).chunk(2, dim=-1)
        # squash log_std into [min, max] smoothly, as the reference does
        log_std = self.log_std_min + 0.5 * (self.log_std_max - self.log_std_min) * (torch.tanh(log_std) + 1)
        if not sample:
            return torch.tanh(mu), None, None, log_std
        noise = torch.randn_like(mu)
        pi = mu + noise * log_std.exp()
        log_pi = (-0.5 * noise.pow(2) - log_std).sum(-1, keepdim=True) - 0.5 * math.log(2 * math.pi) * mu.size(-1)
        pi = torch.tanh(pi)
        # change of variables for tanh (SAC, Haarnoja et al. 2018, appendix C)
        log_pi = log_pi - torch.log(torch.relu(1 - pi.pow(2)) + 1e-6).sum(-1, keepdim=True)
        return torch.tanh(mu), pi, log_pi, log_std


class Critic(nn.Module):
    """Twin Q-functions on the encoder's latent and the action."""

    def __init__(self, encoder: Encoder | IdentityEncoder, action_dim: int, hidden_dim: int) -> None:
        super().__init__()
        self.encoder = encoder
        self.q1 = mlp(encoder.feature_dim + action_dim, hidden_dim, 1)
        self.q2 = mlp(encoder.feature_dim + action_dim, hidden_dim, 1)

    def forward(self, features: torch.Tensor, action: torch.Tensor,
                detach_trunk: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
        """``(Q1, Q2)``, each ``(B, 1)``, from trunk features ``(B, F)`` and actions ``(B, A)``."""
        za = torch.cat([self.encoder.head(features, detach_trunk), action], dim=-1)
        return self.q1(za), self.q2(za)


class TransitionModel(nn.Module):
    """P(z' | z, a): a Gaussian with mean ``(B, Z)`` and std ``(B, Z)`` (probabilistic), or a
    point prediction whose std is None (deterministic)."""

    def __init__(self, latent_dim: int, action_dim: int, width: int, probabilistic: bool,
                 sigma_min: float, sigma_max: float) -> None:
        super().__init__()
        self.body = nn.Sequential(nn.Linear(latent_dim + action_dim, width), nn.LayerNorm(width), nn.ReLU())
        self.fc_mu = nn.Linear(width, latent_dim)
        self.fc_sigma = nn.Linear(width, latent_dim) if probabilistic else None
        self.sigma_min, self.sigma_max = sigma_min, sigma_max

    def forward(self, z: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        x = self.body(torch.cat([z, action], dim=-1))
        if self.fc_sigma is None:
            return self.fc_mu(x), None
        sigma = self.sigma_min + (self.sigma_max - self.sigma_min) * torch.sigmoid(self.fc_sigma(x))
        return self.fc_mu(x), sigma

    def sample(self, z: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """One reparameterised draw of z' ``(B, Z)`` (the mean when deterministic)."""
        mu, sigma = self(z, action)
        return mu if sigma is None else mu + sigma * torch.randn_like(sigma)


def reward_decoder(latent_dim: int, width: int) -> nn.Sequential:
    """R(z'): ``(B, Z) -> (B, 1)``, the reference's ``Linear -> LayerNorm -> ReLU -> Linear``."""
    return nn.Sequential(nn.Linear(latent_dim, width), nn.LayerNorm(width), nn.ReLU(), nn.Linear(width, 1))
