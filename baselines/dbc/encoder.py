"""Observation encoders of DBC: a conv stack (pixels) or an MLP (vectors) to a LayerNorm'd latent,
or the identity on state vectors (``algo.dbc.encoder=identity``: state SAC, no representation).

The pixel encoder is the reference's ``PixelEncoder`` (deep_bisim4control/encoder.py): uint8
frames / 255, a 3x3 conv with stride 2, ``num_layers - 1`` 3x3 convs with stride 1, ReLU after
each, then Linear and LayerNorm (no tanh, unlike SAC-AE). The actor and critic share the conv
stack (the reference ties the weights); each has its own Linear + LayerNorm head.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence

import torch
import torch.nn as nn

# Builds the module that runs the pixel encoder's conv layers. The default is a plain Sequential
# (fp32, the contiguous layout); a caller passes its own to choose layout and precision (the suite:
# plls_bench.repr.pixel_trunk.conv_stack), so this package imports nothing of the suite.
ConvStack = Callable[[Sequence[nn.Module]], nn.Module]


def plain_conv_stack(layers: Sequence[nn.Module]) -> nn.Module:
    """The conv layers as they are, in a ``Sequential`` (its ``state_dict`` keys are every conv
    stack's: ``convs.0.weight``, ...)."""
    return nn.Sequential(*layers)


def weight_init(module: nn.Module) -> None:
    """The reference's init: orthogonal Linear weights, delta-orthogonal convs, zero biases."""
    if isinstance(module, nn.Linear):
        nn.init.orthogonal_(module.weight)
        nn.init.zeros_(module.bias)
    elif isinstance(module, nn.Conv2d):
        # delta-orthogonal (Xiao et al. 2018): an orthogonal matrix at the kernel's centre only
        nn.init.zeros_(module.weight)
        nn.init.zeros_(module.bias)
        mid = module.weight.size(2) // 2
        nn.init.orthogonal_(module.weight.data[:, :, mid, mid], nn.init.calculate_gain("relu"))


class ConvTrunk(nn.Module):
    """``(B, C, H, W)`` uint8 or float pixels in [0, 255] -> ``(B, F)`` flattened conv features,
    float32; the convs run in the module ``conv_stack`` builds of them (layout and precision are
    the caller's)."""

    def __init__(self, obs_shape: tuple[int, ...], num_layers: int, num_filters: int,
                 conv_stack: ConvStack = plain_conv_stack) -> None:
        super().__init__()
        channels = obs_shape[0]
        layers: list[nn.Module] = []
        for i in range(num_layers):
            layers += [nn.Conv2d(channels if i == 0 else num_filters, num_filters, 3,
                                 stride=2 if i == 0 else 1), nn.ReLU()]
        self.convs = conv_stack(layers)
        with torch.no_grad():
            self.out_dim = int(self.convs(torch.zeros(1, *obs_shape)).numel())

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.convs(obs.float() / 255.0).flatten(1)


class MLPTrunk(nn.Module):
    """``(B, D)`` vector observations -> ``(B, hidden)``; a suite addition for state inputs (the
    reference feeds states through an identity encoder, which cannot learn a bisimulation metric)."""

    def __init__(self, obs_shape: tuple[int, ...], hidden_dim: int) -> None:
        super().__init__()
        self.net = nn.Sequential(nn.Linear(obs_shape[0], hidden_dim), nn.ReLU(),
                                 nn.Linear(hidden_dim, hidden_dim), nn.ReLU())
        self.out_dim = hidden_dim

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net(obs.float())


class Encoder(nn.Module):
    """A trunk (possibly shared) and its own ``Linear -> LayerNorm`` head: obs -> ``(B, feature_dim)``."""

    def __init__(self, trunk: nn.Module, feature_dim: int) -> None:
        super().__init__()
        self.trunk = trunk
        self.fc = nn.Linear(trunk.out_dim, feature_dim)
        self.ln = nn.LayerNorm(feature_dim)
        self.feature_dim = feature_dim

    def forward(self, obs: torch.Tensor, detach_trunk: bool = False) -> torch.Tensor:
        return self.head(self.features(obs), detach_trunk)

    def features(self, obs: torch.Tensor) -> torch.Tensor:
        """The trunk's output ``(B, F)``; computed once, it can feed several heads."""
        return self.trunk(obs)

    def head(self, features: torch.Tensor, detach_trunk: bool = False) -> torch.Tensor:
        """``detach_trunk`` stops gradients into the (shared) trunk, as the reference's actor does."""
        return self.ln(self.fc(features.detach() if detach_trunk else features))


class IdentityEncoder(nn.Module):
    """State SAC's "encoder": ``(B, D)`` vectors passed on unchanged (as float32), no parameters.

    SAC-AE's ``IdentityEncoder`` (denisyarats/pytorch_sac_ae encoder.py, ``--encoder_type
    identity``), the state-based SAC baseline CURL and DrQ compare with. It has the
    :class:`Encoder` interface so the actor and critic use either unchanged."""

    def __init__(self, obs_shape: tuple[int, ...]) -> None:
        super().__init__()
        if len(obs_shape) != 1:
            raise ValueError(f"the identity encoder takes (D,) state vectors, got observation shape {obs_shape}")
        self.trunk = IdentityTrunk(obs_shape[0])
        self.fc, self.ln = nn.Identity(), nn.Identity()
        self.feature_dim = obs_shape[0]

    def forward(self, obs: torch.Tensor, detach_trunk: bool = False) -> torch.Tensor:
        return self.features(obs)

    def features(self, obs: torch.Tensor) -> torch.Tensor:
        return self.trunk(obs)

    def head(self, features: torch.Tensor, detach_trunk: bool = False) -> torch.Tensor:
        return features


class IdentityTrunk(nn.Module):
    """``(B, D)`` -> the same ``(B, D)`` as float32."""

    def __init__(self, dim: int) -> None:
        super().__init__()
        self.out_dim = dim

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return obs.float()


def make_trunk(obs_shape: tuple[int, ...], num_layers: int, num_filters: int,
               mlp_hidden: int, conv_stack: ConvStack = plain_conv_stack) -> nn.Module:
    """Conv trunk for ``(C, H, W)`` pixels (its convs run by ``conv_stack``), MLP trunk for ``(D,)`` vectors."""
    if len(obs_shape) == 3:
        return ConvTrunk(obs_shape, num_layers, num_filters, conv_stack)
    if len(obs_shape) == 1:
        return MLPTrunk(obs_shape, mlp_hidden)
    raise ValueError(f"DBC encodes (C, H, W) pixels or (D,) vectors, got observation shape {obs_shape}")
