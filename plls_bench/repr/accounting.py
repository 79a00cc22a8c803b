"""Parameter accounting (Table 3) and layer-by-layer architecture summaries (Figs. 12 and 17).

Both take the modules a method needs *at run time*, by name: for PL-LS + PPO that is V_s's
encoder, V_a's decoder and the policy, of which only the policy is trainable by the RL.
"""
from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import torch
from torch import Tensor, nn


def _count(module: nn.Module, only_trainable: bool) -> int:
    return sum(p.numel() for p in module.parameters() if p.requires_grad or not only_trainable)


def parameter_counts(modules: dict[str, nn.Module], trainable: Iterable[str]) -> dict[str, Any]:
    """``params.json``: ``total``, ``trainable`` and ``modules: {name: {total, trainable}}``.

    ``trainable`` names the modules the learner updates; a module not named counts as frozen
    even if its tensors still have ``requires_grad`` (the learner's optimizer never sees them).
    Parameters shared between modules are counted once in the totals.
    """
    trainable = set(trainable)
    unknown = trainable - set(modules)
    if unknown:
        raise KeyError(f"trainable names {sorted(unknown)} are not among the modules {sorted(modules)}")
    per_module = {name: {"total": _count(m, False), "trainable": _count(m, True) if name in trainable else 0}
                  for name, m in modules.items()}
    seen: dict[int, bool] = {}  # parameter id -> trainable by the learner
    for name, module in modules.items():
        for p in module.parameters():
            seen[id(p)] = seen.get(id(p), False) or (name in trainable and p.requires_grad)
    sizes = {id(p): p.numel() for m in modules.values() for p in m.parameters()}
    return {"total": sum(sizes.values()),
            "trainable": sum(sizes[i] for i, flag in seen.items() if flag),
            "modules": per_module}


def _shape(output: Any) -> Any:
    """Output shape(s) as lists, batch dimension included; tuples of tensors give a list of them."""
    if isinstance(output, Tensor):
        return list(output.shape)
    if isinstance(output, (tuple, list)):
        return [_shape(o) for o in output]
    return None


def _layers(module: nn.Module, example: Tensor) -> list[dict[str, Any]]:
    """Run ``module`` on ``example`` and record each leaf module call in call order."""
    rows: list[dict[str, Any]] = []
    hooks = []
    for name, sub in module.named_modules():
        if next(sub.children(), None) is not None:
            continue  # containers: their leaves are recorded instead
        own = list(sub.parameters(recurse=False))

        def hook(mod: nn.Module, _inputs: Any, output: Any, name: str = name, own: list = own) -> None:
            rows.append({"name": name, "type": type(mod).__name__, "output_shape": _shape(output),
                         "params": sum(p.numel() for p in own),
                         "trainable": sum(p.numel() for p in own if p.requires_grad)})
        hooks.append(sub.register_forward_hook(hook))
    param = next(module.parameters(), None)
    if param is not None:  # callers build examples on the CPU; the module may sit on a GPU
        example = example.to(param.device)
    was_training = module.training
    module.eval()  # no dropout / running-statistics updates from a summary pass
    try:
        with torch.inference_mode():
            module(example)
    finally:
        module.train(was_training)
        for handle in hooks:
            handle.remove()
    return rows


def architecture_summary(modules: dict[str, nn.Module], example_inputs: dict[str, Tensor]) -> dict[str, Any]:
    """``architecture.json``: per module, its leaf layers in call order with ``name``, ``type``,
    ``output_shape`` (for the example batch), ``params`` and ``trainable`` (parameter counts).

    ``example_inputs[name]`` is a batch the module accepts, e.g. ``torch.zeros(1, 3, 96, 96)``.
    """
    missing = set(modules) - set(example_inputs)
    if missing:
        raise KeyError(f"architecture_summary needs an example input for {sorted(missing)}")
    return {name: _layers(module, example_inputs[name]) for name, module in modules.items()}
