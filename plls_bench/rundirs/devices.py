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


def cpu_model(cpuinfo: str | None = None) -> str:
    """The CPU's marketing name, with the generation and vector units that set its speed.

    A name alone can hide a 3x gap: "AMD EPYC" is both a Zen 1 (family 23, AVX2) and a Zen 4
    (family 25, AVX-512) VM, and CNN training differs by that much between them. ``cpuinfo`` is
    the text of /proc/cpuinfo (read here when None); off Linux, what :mod:`platform` knows. No
    commas: machine lines are split on them (:func:`plls_bench.pipeline.rates.rate_machines`)."""
    if cpuinfo is None:
        try:
            cpuinfo = Path("/proc/cpuinfo").read_text()
        except OSError:
            cpuinfo = ""
    fields: dict[str, str] = {}
    for line in cpuinfo.splitlines():
        key, sep, value = line.partition(":")
        if not sep:
            if fields:  # the first processor's block is enough
                break
            continue
        fields.setdefault(key.strip(), value.strip())
    name = fields.get("model name") or platform.processor() or platform.machine() or "unknown CPU"
    flags = set(fields.get("flags", "").split())
    units = next((label for flag, label in (("avx512f", "AVX-512"), ("avx2", "AVX2"), ("sse4_2", "SSE4.2"))
                  if flag in flags), None)
    detail = [f"family {fields['cpu family']} model {fields.get('model', '?')}"] if "cpu family" in fields else []
    detail += [units] if units else []
    return f"{name} ({'; '.join(detail)})" if detail else name
