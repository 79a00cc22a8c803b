"""STAND-IN until issue 3 lands plls_bench/repr/accounting.py (same signatures); replaced at merge."""
from __future__ import annotations

from typing import Any, Iterable

import torch
from torch import Tensor, nn


def parameter_counts(modules: dict[str, nn.Module], trainable: Iterable[str]) -> dict[str, Any]:
    names = set(trainable)
    per = {n: {"total": sum(p.numel() for p in m.parameters()),
               "trainable": sum(p.numel() for p in m.parameters()) if n in names else 0}
           for n, m in modules.items()}
    return {"total": sum(v["total"] for v in per.values()),
            "trainable": sum(v["trainable"] for v in per.values()), "modules": per}


def architecture_summary(modules: dict[str, nn.Module], example_inputs: dict[str, Tensor]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, module in modules.items():
        rows: list[dict[str, Any]] = []
        hooks = [sub.register_forward_hook(
            lambda m, i, o, n=n: rows.append({"name": n, "type": type(m).__name__,
                                              "output_shape": list(o.shape) if isinstance(o, Tensor) else None,
                                              "params": sum(p.numel() for p in m.parameters(recurse=False)),
                                              "trainable": sum(p.numel() for p in m.parameters(recurse=False))}))
            for n, sub in module.named_modules() if next(sub.children(), None) is None]
        with torch.inference_mode():
            module(example_inputs[name])
        for h in hooks:
            h.remove()
        out[name] = rows
    return out
