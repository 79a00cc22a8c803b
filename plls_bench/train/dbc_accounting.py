"""``metrics/params.json`` and ``metrics/architecture.json`` of a DBC run (README contract).

Modules: ``encoder`` (the critic's conv trunk, shared with the actor, and its Linear + LayerNorm),
``actor`` (its own Linear + LayerNorm head and MLP), ``critic`` (twin Q), ``critic_target``
(Polyak-averaged, so not trainable), ``transition_model``, ``reward_decoder`` and, for PL-LS, the
frozen ``action_decoder`` (V_a's decoder). Shared parameters are counted once. Output shapes are
recorded by hooks during one probe forward pass on a batch of one (batch dimension included);
``trainable`` is the number of parameters the learner updates.
"""
from __future__ import annotations

from typing import Any

import torch
import torch.nn as nn

from baselines.dbc import DBCAgent
from plls_bench.runs import Run


def module_groups(agent: DBCAgent) -> dict[str, tuple[nn.Module, bool]]:
    """name -> (module, trainable by gradient) for every part of the agent, shared parts once."""
    actor, critic = agent.actor, agent.critic
    return {
        "encoder": (critic.encoder, True),
        "actor": (nn.ModuleDict({"encoder_fc": actor.encoder.fc, "encoder_ln": actor.encoder.ln,
                                 "trunk": actor.trunk}), True),
        "critic": (nn.ModuleDict({"q1": critic.q1, "q2": critic.q2}), True),
        "critic_target": (agent.critic_target, False),
        "transition_model": (agent.transition, True),
        "reward_decoder": (agent.reward_decoder, True),
    }


def _probe(agent: DBCAgent, obs_shape: tuple[int, ...]) -> None:
    """One forward pass through every module (batch of one zero observation)."""
    obs = torch.zeros(1, *obs_shape, device=agent.device)
    with torch.no_grad():
        features = agent.critic.encoder.features(obs)
        z = agent.critic.encoder.head(features)
        _, action, _, _ = agent.actor(features)
        agent.critic(features, action)
        agent.critic_target(agent.critic_target.encoder.features(obs), action)
        agent.reward_decoder(agent.transition.sample(z, action))


def _is_leaf(module: nn.Module) -> bool:
    return next(module.children(), None) is None


def _layers(module: nn.Module, trainable: bool, shapes: dict[int, list[int]]) -> list[dict[str, Any]]:
    rows = []
    for name, leaf in module.named_modules():
        if not _is_leaf(leaf):
            continue
        count = sum(p.numel() for p in leaf.parameters(recurse=False))
        rows.append({"name": name, "type": type(leaf).__name__, "output_shape": shapes.get(id(leaf)),
                     "params": count, "trainable": count if trainable else 0})
    return rows


def accounting(agent: DBCAgent, obs_shape: tuple[int, ...],
               extra: dict[str, nn.Module] | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(params, architecture)`` in the README's format; ``extra`` modules are frozen (V_a)."""
    groups = {**module_groups(agent), **{k: (m, False) for k, m in (extra or {}).items()}}
    shapes: dict[int, list[int]] = {}
    def record(module: nn.Module, _inputs: Any, output: torch.Tensor) -> None:
        shapes.setdefault(id(module), list(output.shape))

    hooks = [leaf.register_forward_hook(record)
             for module, _ in groups.values() for leaf in module.modules() if _is_leaf(leaf)]
    try:
        _probe(agent, obs_shape)
    finally:
        for hook in hooks:
            hook.remove()
    modules = {name: {"total": sum(p.numel() for p in m.parameters()),
                      "trainable": sum(p.numel() for p in m.parameters()) if trainable else 0}
               for name, (m, trainable) in groups.items()}
    params = {"total": sum(v["total"] for v in modules.values()),
              "trainable": sum(v["trainable"] for v in modules.values()), "modules": modules}
    architecture = {name: _layers(m, trainable, shapes) for name, (m, trainable) in groups.items()}
    return params, architecture


def write_accounting(run: Run, agent: DBCAgent, venv: Any) -> None:
    """Write both files for the agent acting in ``venv`` (V_a's decoder included when wrapped)."""
    decoder = getattr(venv, "decoder", None)
    extra = {"action_decoder": decoder} if isinstance(decoder, nn.Module) else None
    params, architecture = accounting(agent, venv.observation_space.shape, extra)
    run.write_json("metrics/params.json", params)
    run.write_json("metrics/architecture.json", architecture)
