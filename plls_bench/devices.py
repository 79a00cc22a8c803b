"""The one place that turns a ``device`` setting (``cpu`` / ``cuda`` / ``auto``) into a torch device.

Every runner, loader and report tool goes through :func:`resolve_device`, so ``auto`` means the
same everywhere: the first CUDA GPU when torch sees one, else the CPU. The settings a config may
name (``DEVICES``) are the config layer's, below this module. torch is imported lazily: the command
line is validated without loading torch unless a GPU is asked for.
"""
from __future__ import annotations

import os
import platform
from pathlib import Path
from typing import TYPE_CHECKING

from plls_bench.config import DEVICES, ConfigError

if TYPE_CHECKING:
    import torch


def cuda_available() -> bool:
    """Whether torch can use a CUDA GPU here (False without torch's CUDA build or a driver)."""
    import torch

    return torch.cuda.is_available()


def require_device(name: str, key: str = "device") -> None:
    """Refuse a device this machine does not have, with one line naming ``key``.

    Availability is a property of the machine running a command, not of a config: it is checked
    where a command is about to compute (the CLI, a runner's start, a loader), never when a
    recorded config is read back, so a run made on a GPU machine stays readable on a CPU one.
    """
    if name not in DEVICES:
        raise ConfigError(f"{key}: unknown value {name!r}; choose one of {', '.join(DEVICES)}")
    if name == "cuda" and not cuda_available():
        raise ConfigError(f"{key}: cuda was asked for but torch sees no CUDA GPU on this machine; "
                          f"use {key}=auto (cuda when present, else cpu) or {key}=cpu")


def resolve_device(name: str, key: str = "device") -> torch.device:
    """``cpu`` / ``cuda`` / ``auto`` as a torch device; a GPU carries its index (``cuda:0``)."""
    import torch

    require_device(name, key)
    if name == "cpu" or (name == "auto" and not torch.cuda.is_available()):
        return torch.device("cpu")
    return torch.device("cuda", torch.cuda.current_device())


def device_name(device: torch.device) -> str:
    """The hardware behind ``device``: the GPU's name, or the CPU's model and core count."""
    import torch

    if device.type == "cuda":
        return torch.cuda.get_device_name(device)
    return f"{cpu_model()}, {os.cpu_count()} cores"


def cpu_model() -> str:
    """The CPU's marketing name from /proc/cpuinfo (Linux), else what :mod:`platform` knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"
