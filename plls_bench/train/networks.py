"""The paper's shared policy/value networks as stable-baselines3 features extractors.

The paper shares one network between policy and value (Sec. 5.1, 5.2). SB3 2.x builds separate
MLPs for pi and vf from ``net_arch``, so the shared trunk is a features extractor used by both
(``share_features_extractor=True``) and the heads are linear (``net_arch=[]``): the Gaussian's mean
and the value are each one linear layer on the trunk's output, plus SB3's state-independent log-std.

Raw CarRacing frames reach the policy as uint8 ``(3, 96, 96)``; SB3's ``preprocess_obs`` divides a
uint8 image Box by 255 before the extractor (``normalize_images``), so :class:`PaperCNN` sees float32
in [0, 1], bit for bit the frames it saw when the envs returned float32.
"""
from __future__ import annotations

from typing import Any

import gymnasium as gym
import torch
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from plls_bench.config import PPOConfig
from plls_bench.repr.pixel_trunk import PixelTrunk, to_channels_last

ACTIVATIONS: dict[str, type[nn.Module]] = {"tanh": nn.Tanh, "relu": nn.ReLU}


def _fully_connected(in_dim: int, widths: list[int], activation: str) -> nn.Sequential:
    layers: list[nn.Module] = []
    for width in widths:
        layers += [nn.Linear(in_dim, width), ACTIVATIONS[activation]()]
        in_dim = width
    return nn.Sequential(*layers)


class SharedMLP(BaseFeaturesExtractor):
    """Vector observations ``(B, D)`` -> ``(B, hidden[-1])`` through fully connected layers."""

    def __init__(self, observation_space: gym.spaces.Box, hidden: list[int], activation: str) -> None:
        if len(observation_space.shape) != 1:
            raise ValueError(f"SharedMLP needs vector observations, got shape {observation_space.shape}")
        in_dim = int(observation_space.shape[0])
        super().__init__(observation_space, features_dim=hidden[-1] if hidden else in_dim)
        self.mlp = _fully_connected(in_dim, hidden, activation)

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        return self.mlp(observations)


class PaperCNN(BaseFeaturesExtractor):
    """Images ``(B, C, H, W)`` in [0, 1] -> ``(B, hidden[-1])``: conv layers (ReLU, as V_s's
    encoder), flatten, then fully connected layers (Sec. 5.2: "four convolutional layers and two
    fully connected layers"). The conv layers are a :class:`PixelTrunk` run in ``precision``
    (its output float32); the fully connected layers stay fp32."""

    def __init__(self, observation_space: gym.spaces.Box, channels: list[int], kernel_sizes: list[int],
                 stride: int, hidden: list[int], activation: str, precision: str = "fp32") -> None:
        if len(observation_space.shape) != 3:
            raise ValueError(f"PaperCNN needs (C, H, W) images, got shape {observation_space.shape}")
        convs: list[nn.Module] = []
        in_ch = int(observation_space.shape[0])
        for width, kernel in zip(channels, kernel_sizes):
            convs += [nn.Conv2d(in_ch, width, kernel, stride=stride), nn.ReLU()]
            in_ch = width
        convs.append(nn.Flatten())
        conv = PixelTrunk(*convs, precision=precision)
        with torch.no_grad():
            flat = int(conv(torch.zeros(1, *observation_space.shape)).shape[1])
        super().__init__(observation_space, features_dim=hidden[-1] if hidden else flat)
        self.conv = conv
        self.fc = _fully_connected(flat, hidden, activation)

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        return self.fc(self.conv(observations))


class ChannelsLastPolicy(ActorCriticPolicy):
    """SB3's ``ActorCriticPolicy`` with its conv weights in channels_last (:mod:`plls_bench.repr.pixel_trunk`),
    converted after SB3's orthogonal init: ``nn.init.orthogonal_`` writes through ``.view``, which a
    channels_last weight refuses. A policy without convs is unchanged."""

    def _build(self, lr_schedule: Any) -> None:
        super()._build(lr_schedule)
        to_channels_last(self)  # in place: the optimiser built above keeps the same parameters


def policy_kwargs(ppo: PPOConfig, precision: str = "fp32") -> dict[str, Any]:
    """SB3 ``policy_kwargs`` building the configured shared trunk with linear heads, or SB3's own
    ``MlpPolicy`` networks (``separate_mlp``: separate pi and vf MLPs, as rl-baselines3-zoo runs).
    ``precision`` is the run's (``cfg.precision``), for the conv trunk of ``paper_cnn``."""
    if ppo.features_extractor == "separate_mlp":
        hidden = list(ppo.policy_hidden)
        return {"net_arch": {"pi": hidden, "vf": hidden}, "activation_fn": ACTIVATIONS[ppo.activation],
                "log_std_init": ppo.log_std_init, "ortho_init": ppo.ortho_init}
    if ppo.features_extractor == "mlp":
        extractor: type[BaseFeaturesExtractor] = SharedMLP
        kwargs: dict[str, Any] = {"hidden": list(ppo.policy_hidden), "activation": ppo.activation}
    else:
        extractor = PaperCNN
        kwargs = {"channels": list(ppo.cnn_channels), "kernel_sizes": list(ppo.cnn_kernel_sizes),
                  "stride": ppo.cnn_stride, "hidden": list(ppo.cnn_hidden), "activation": ppo.activation,
                  "precision": precision}
    return {"features_extractor_class": extractor, "features_extractor_kwargs": kwargs,
            "share_features_extractor": True, "net_arch": [], "log_std_init": ppo.log_std_init,
            "ortho_init": ppo.ortho_init}
