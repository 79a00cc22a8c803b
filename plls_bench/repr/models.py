"""The two VAEs of PL-LS: V_a over actions (Eq. 3) and V_s over CarRacing frames (Eq. 2).

Both split into an ``encoder`` (a :class:`GaussianEncoder`: input -> mean and std of q(.|x)) and a
``decoder`` (latent -> the mean of p(x|.)), so the run-time pieces PL-LS keeps (V_s's encoder,
V_a's decoder) can be counted and summarised on their own.
"""
from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from plls_bench.config import ActionReprConfig, StateReprConfig
from plls_bench.repr.pixel_trunk import PixelTrunk, to_channels_last

_ACTIVATIONS: dict[str, type[nn.Module]] = {"relu": nn.ReLU, "elu": nn.ELU, "tanh": nn.Tanh}


def mlp(sizes: list[int], activation: str) -> nn.Sequential:
    """Linear layers between consecutive ``sizes``, each followed by the activation."""
    layers: list[nn.Module] = []
    for n_in, n_out in zip(sizes[:-1], sizes[1:]):
        layers += [nn.Linear(n_in, n_out), _ACTIVATIONS[activation]()]
    return nn.Sequential(*layers)


class GaussianEncoder(nn.Module):
    """``trunk`` features -> (mu, std) of a diagonal Gaussian posterior, both ``(B, latent_dim)``."""

    def __init__(self, trunk: nn.Module, features: int, latent_dim: int) -> None:
        super().__init__()
        self.trunk = trunk
        self.mu = nn.Linear(features, latent_dim)
        self.log_var = nn.Linear(features, latent_dim)

    def forward(self, x: Tensor) -> tuple[Tensor, Tensor]:
        h = self.trunk(x)
        return self.mu(h), torch.exp(0.5 * self.log_var(h))


class VAE(nn.Module):
    """Shared VAE mechanics: reparameterised sampling and the negative ELBO of Eqs. (2)-(3)."""

    encoder: GaussianEncoder
    decoder: nn.Module

    def __init__(self, latent_dim: int, likelihood_std: float, kl_weight: float) -> None:
        super().__init__()
        self.latent_dim = latent_dim
        self.likelihood_std = likelihood_std
        self.kl_weight = kl_weight

    def encode(self, x: Tensor) -> tuple[Tensor, Tensor]:
        """Posterior mean and std, ``(B, latent_dim)`` each."""
        return self.encoder(x)

    def decode(self, z: Tensor) -> Tensor:
        """The decoder mean for latents ``z`` of shape ``(B, latent_dim)``."""
        return self.decoder(z)

    def forward(self, x: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """(x_hat, mu, std): x_hat decodes one sample z = mu + std * eps (reparameterisation)."""
        mu, std = self.encode(x)
        z = mu + std * torch.randn_like(std)
        return self.decode(z), mu, std

    def loss(self, x: Tensor) -> dict[str, Tensor]:
        """Negative ELBO per sample, averaged over the batch, without its additive constant.

        -log p(x|z) = |x - x_hat|^2 / (2 s^2) + D log(s sqrt(2 pi)) for a Gaussian decoder of fixed
        std s (``likelihood_std``); the constant is dropped, so ``loss`` = recon term + w * KL.
        Also returns ``recon_mse`` (per element) and ``kl`` (per sample, nats).
        """
        x_hat, mu, std = self(x)
        sq_err = (x_hat - x).pow(2).flatten(1)
        kl = 0.5 * (mu.pow(2) + std.pow(2) - 1.0 - 2.0 * torch.log(std)).sum(dim=1)
        recon = sq_err.sum(dim=1) / (2.0 * self.likelihood_std ** 2)
        return {"loss": (recon + self.kl_weight * kl).mean(), "recon_mse": sq_err.mean(),
                "kl": kl.mean()}


class ActionVAE(VAE):
    """V_a: ``(B, A)`` actions <-> ``(B, N_e)`` latents through MLPs (Sec. 5.1, 5.2, 5.3)."""

    def __init__(self, cfg: ActionReprConfig, action_dim: int) -> None:
        super().__init__(cfg.latent_dim, cfg.likelihood_std, cfg.kl_weight)
        self.action_dim = action_dim
        enc = [action_dim, *cfg.encoder_hidden]
        self.encoder = GaussianEncoder(mlp(enc, cfg.activation), enc[-1], cfg.latent_dim)
        dec = [cfg.latent_dim, *cfg.decoder_hidden]
        # The output layer is linear: it is the Gaussian mean; callers clip to the env's bounds.
        self.decoder = nn.Sequential(mlp(dec, cfg.activation), nn.Linear(dec[-1], action_dim))


class StateVAE(VAE):
    """V_s: ``(B, 3, H, W)`` frames in [0, 1] <-> ``(B, N_z)`` latents (Sec. 5.2, Fig. 12).

    The encoder's conv stack and the whole decoder are :class:`PixelTrunk` s: channels_last, in
    ``precision`` (the run's ``cfg.precision``); the posterior heads (mu, log_var) stay fp32."""

    def __init__(self, cfg: StateReprConfig, image_size: int, in_channels: int = 3,
                 precision: str = "fp32") -> None:
        super().__init__(cfg.latent_dim, cfg.likelihood_std, cfg.kl_weight)
        self.image_shape = (in_channels, image_size, image_size)
        widths = [in_channels, *cfg.channels]
        convs: list[nn.Module] = []
        for n_in, n_out, kernel in zip(widths[:-1], widths[1:], cfg.kernel_sizes):
            convs += [nn.Conv2d(n_in, n_out, kernel, stride=2), nn.ReLU()]
        side = cfg.feature_sizes(image_size)[-1]
        self.feature_shape = (cfg.channels[-1], side, side)
        features = math.prod(self.feature_shape)
        self.encoder = GaussianEncoder(PixelTrunk(*convs, nn.Flatten(), precision=precision), features,
                                       cfg.latent_dim)
        back = [cfg.channels[-1], *reversed(cfg.channels[:-1]), in_channels]
        deconvs: list[nn.Module] = []
        for i, (n_in, n_out, kernel) in enumerate(zip(back[:-1], back[1:], cfg.deconv_kernel_sizes)):
            last = i == len(cfg.deconv_kernel_sizes) - 1
            # sigmoid on the last layer: pixels are in [0, 1] (Sec. 5.2)
            deconvs += [nn.ConvTranspose2d(n_in, n_out, kernel, stride=2), nn.Sigmoid() if last else nn.ReLU()]
        # FC z -> feature map without an activation, as World Models' decoder ("dec_fc")
        self.decoder = PixelTrunk(nn.Linear(cfg.latent_dim, features), nn.Unflatten(1, self.feature_shape),
                                  *deconvs, precision=precision)
        to_channels_last(self)
