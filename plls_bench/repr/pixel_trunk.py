"""How the suite's conv trunks compute: memory layout (channels_last) and precision (fp32 | bf16).

Every pixel network (plain PPO's ``paper_cnn`` extractor, V_s's encoder and decoder, DBC's pixel
encoder, whose conv layers :func:`conv_stack` wraps for ``baselines.dbc``) runs its conv layers
through a :class:`PixelTrunk`:

- **channels_last.** Conv weights are converted once (:func:`to_channels_last`) and activations
  enter each conv layer in the layout of the weights (oneDNN's fast path on CPU, cuDNN's NHWC on
  GPUs). Only the order of float sums changes, as with the thread count, so it is hash-neutral and
  always on. Flattening a channels_last map copies it to the logical ``(C, H, W)`` order, so
  features, weights and checkpoints are the same in either layout.
- **precision.** ``bf16`` runs the trunk under ``torch.autocast(dtype=torch.bfloat16)``; its output
  is cast back to float32 at the exit, so heads, losses, value targets, optimiser state and the
  parameters themselves stay fp32. ``fp32`` (the paper's) is plain float32.
"""
from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence

import torch
from torch import Tensor, nn

from plls_bench.config import PRECISIONS

_CONVS = (nn.Conv2d, nn.ConvTranspose2d)

__all__ = ["PRECISIONS", "PixelTrunk", "autocast", "conv_stack", "memory_format", "pixels_to_unit", "to_channels_last"]


def autocast(precision: str, device: torch.device) -> contextlib.AbstractContextManager:
    """bf16 autocast on ``device``'s type for ``precision="bf16"``; a no-op context for fp32."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)}, got {precision!r}")
    return torch.autocast(device_type=device.type, dtype=torch.bfloat16, enabled=precision == "bf16")


def to_channels_last(module: nn.Module) -> nn.Module:
    """``module`` with its 4-D parameters (conv weights) in channels_last, in place."""
    return module.to(memory_format=torch.channels_last)


def memory_format(module: nn.Module) -> torch.memory_format:
    """The layout of ``module``'s first conv weight: channels_last once converted, else contiguous."""
    for layer in module.modules():
        if isinstance(layer, _CONVS):
            converted = layer.weight.is_contiguous(memory_format=torch.channels_last)
            return torch.channels_last if converted else torch.contiguous_format
    return torch.contiguous_format


def pixels_to_unit(x: Tensor) -> Tensor:
    """uint8 pixels -> float32 in [0, 1] (``x / 255``, exactly as V_s's training batches); float
    input is taken as already scaled."""
    return x.float().div_(255.0) if x.dtype == torch.uint8 else x.float()


class PixelTrunk(nn.Sequential):
    """A ``Sequential`` of conv / deconv layers (and the flatten, unflatten or linear layers around
    them) run in its conv weights' layout and in ``precision``; float32 out (for float32 input).

    A ``Sequential`` subclass, so its ``state_dict`` keys are those of the plain ``Sequential`` it
    replaces: artifacts and checkpoints saved before it load unchanged."""

    def __init__(self, *layers: nn.Module, precision: str = "fp32") -> None:
        super().__init__(*layers)
        autocast(precision, torch.device("cpu"))  # validates the name
        self.precision = precision

    def forward(self, x: Tensor) -> Tensor:
        layout = memory_format(self)
        with autocast(self.precision, x.device):
            for layer in self:
                if isinstance(layer, _CONVS):
                    x = x.contiguous(memory_format=layout)  # no copy once in that layout
                x = layer(x)
        return x.float() if x.dtype == torch.bfloat16 else x  # fp32 again at the exit

    def extra_repr(self) -> str:
        return f"precision={self.precision}"


def conv_stack(precision: str = "fp32") -> Callable[[Sequence[nn.Module]], nn.Module]:
    """What builds a network's conv stack the suite's way, for networks defined outside the suite
    (``baselines.dbc``'s pixel encoder takes it as ``conv_stack``): the layers in a channels_last
    :class:`PixelTrunk` run in ``precision`` (channels_last is ~35% faster for DBC's small convs on
    CPU under oneDNN, and fine on GPUs)."""
    autocast(precision, torch.device("cpu"))  # validates the name before any network is built

    def build(layers: Sequence[nn.Module]) -> nn.Module:
        return to_channels_last(PixelTrunk(*layers, precision=precision))

    return build
