"""DBC's representation losses: the bisimulation loss and the latent model losses.

The bisimulation loss (Zhang et al. 2021, Eq. 4) pairs each sample i of a batch with a random
other sample j = perm[i] and regresses the latent distance onto the one-step bisimulation target

    |z_i - z_j|  ~  |r_i - r_j| + gamma * W_2(P(.|z_i, a_i), P(.|z_j, a_j)),

with the target held fixed (no gradient through the transition model). As in the reference
(agent/bisim_agent.py ``update_encoder``), the distances are taken per latent dimension: smooth-L1
for latents and rewards and, for diagonal Gaussians, the per-dimension W_2
``sqrt((mu_i - mu_j)^2 + (sigma_i - sigma_j)^2)``; a deterministic model uses smooth-L1 of the
means (the reference's default transition model ``''``).
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

from baselines.dbc.models import TransitionModel


def bisimulation_target(reward: torch.Tensor, next_mu: torch.Tensor, next_sigma: torch.Tensor | None,
                        perm: torch.Tensor, discount: float) -> torch.Tensor:
    """``(B, Z)`` target distances between samples i and ``perm[i]``; ``reward`` is ``(B, 1)``."""
    r_dist = F.smooth_l1_loss(reward, reward[perm], reduction="none")
    if next_sigma is None:
        transition_dist = F.smooth_l1_loss(next_mu, next_mu[perm], reduction="none")
    else:
        transition_dist = torch.sqrt((next_mu - next_mu[perm]).pow(2) + (next_sigma - next_sigma[perm]).pow(2))
    return r_dist + discount * transition_dist


def bisimulation_loss(z: torch.Tensor, action: torch.Tensor, reward: torch.Tensor,
                      transition: TransitionModel, discount: float,
                      perm: torch.Tensor | None = None) -> torch.Tensor:
    """Mean squared gap between latent distances ``(B, Z)`` and their bisimulation targets.

    ``z`` ``(B, Z)`` carries the encoder's gradient; ``perm`` defaults to a random permutation.
    """
    perm = torch.randperm(z.size(0), device=z.device) if perm is None else perm
    with torch.no_grad():
        next_mu, next_sigma = transition(z, action)
        target = bisimulation_target(reward, next_mu, next_sigma, perm, discount)
    z_dist = F.smooth_l1_loss(z, z[perm], reduction="none")
    return (z_dist - target).pow(2).mean()


def transition_loss(z: torch.Tensor, action: torch.Tensor, next_z: torch.Tensor,
                    transition: TransitionModel) -> torch.Tensor:
    """Gaussian negative log-likelihood (up to a constant) of the detached next latent ``(B, Z)``."""
    mu, sigma = transition(z, action)
    sigma = torch.ones_like(mu) if sigma is None else sigma
    diff = (mu - next_z.detach()) / sigma
    return (0.5 * diff.pow(2) + torch.log(sigma)).mean()


def reward_loss(z: torch.Tensor, action: torch.Tensor, reward: torch.Tensor,
                transition: TransitionModel, decoder: torch.nn.Module) -> torch.Tensor:
    """MSE of the reward ``(B, 1)`` decoded from a sampled predicted next latent."""
    return F.mse_loss(decoder(transition.sample(z, action)), reward)


def latent_batch_std(z: torch.Tensor) -> float:
    """Spread of a batch of latents ``(B, Z)``: the std over the batch, averaged over dimensions.

    Not part of DBC's losses: a diagnostic. The latent is LayerNorm'd per sample, so its norm
    says nothing. An encoder that maps every observation to the same latent (the bisimulation
    loss is satisfied by that when reward differences are small) reads about 0 here."""
    return float(z.detach().std(dim=0).mean())
