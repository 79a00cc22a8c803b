"""``metrics/params.json`` and ``metrics/architecture.json`` of a DBC run, with the shared
helpers of :mod:`plls_bench.repr.accounting`.

Modules: ``encoder`` (the critic's conv trunk, shared with the actor, and its Linear +
LayerNorm), ``actor`` (its own Linear + LayerNorm head and MLP, from the trunk's features),
``critic`` (twin Q on ``[z, a]``), ``critic_target`` (Polyak-averaged: not trainable),
``transition_model`` (on ``[z, a]``), ``reward_decoder`` and, for PL-LS + DBC, the frozen
``V_a.decoder``. State SAC (``algo.dbc.encoder=identity``) has only actor, critic and target; pixel
SAC (``algo.dbc.encoder=critic``) has those and the encoder.
Modules whose forward takes several tensors are summarised through a one-input adapter that runs
the same layers in the same order.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
import torch.nn as nn
from stable_baselines3.common.vec_env import VecEnv

from baselines.dbc import DBCAgent
from plls_bench.repr.accounting import architecture_summary, parameter_counts
from plls_bench.repr.latent_wrappers import latent_modules
from plls_bench.rundirs.run_dir import ARCHITECTURE_FILE, PARAMS_FILE, Run


class _OneInput(nn.Module):
    """``fn(x)`` over ``parts``, so a summary can drive a module that takes several inputs."""

    def __init__(self, fn: Callable[[torch.Tensor], Any], **parts: nn.Module) -> None:
        super().__init__()
        self.parts, self.fn = nn.ModuleDict(parts), fn

    def forward(self, x: torch.Tensor) -> Any:
        return self.fn(x)


def modules_and_examples(agent: DBCAgent, obs_shape: tuple[int, ...],
                         action_dim: int) -> tuple[dict[str, nn.Module], dict[str, torch.Tensor]]:
    """The agent's modules by name, each with an example batch of one it accepts."""
    actor, critic, target, transition = agent.actor, agent.critic, agent.critic_target, agent.transition
    z_dim, features = critic.encoder.feature_dim, critic.encoder.trunk.out_dim

    def split(za: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return za[:, :z_dim], za[:, z_dim:]

    modules = {
        "encoder": critic.encoder,
        "actor": nn.Sequential(actor.encoder.fc, actor.encoder.ln, actor.trunk),
        "critic": _OneInput(lambda za: (critic.q1(za), critic.q2(za)), q1=critic.q1, q2=critic.q2),
        "critic_target": _OneInput(lambda obs: target(target.encoder.features(obs), torch.zeros(
            len(obs), action_dim, device=obs.device)), critic=target),
    }
    zeros = {"obs": torch.zeros(1, *obs_shape), "features": torch.zeros(1, features),
             "z": torch.zeros(1, z_dim), "za": torch.zeros(1, z_dim + action_dim)}
    examples = {"encoder": zeros["obs"], "actor": zeros["features"], "critic": zeros["za"],
                "critic_target": zeros["obs"], "transition_model": zeros["za"], "reward_decoder": zeros["z"]}
    if transition is not None and agent.reward_decoder is not None:
        modules["transition_model"] = _OneInput(lambda za: transition(*split(za)), model=transition)
        modules["reward_decoder"] = agent.reward_decoder
    if not agent.has_encoder:  # state SAC: no encoder (the identity); pixel SAC keeps it, without models
        del modules["encoder"]
    return modules, {k: examples[k].to(agent.device) for k in modules}


def accounting(agent: DBCAgent, venv: VecEnv) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(params, architecture)`` of the agent acting in ``venv`` (V_a's decoder when wrapped)."""
    action_dim = int(venv.action_space.shape[0])
    modules, examples = modules_and_examples(agent, venv.observation_space.shape, action_dim)
    for name, module in latent_modules(venv).items():  # frozen, run by the wrappers
        first = next(m for m in module.modules() if isinstance(m, nn.Linear))
        modules[name], examples[name] = module, torch.zeros(1, first.in_features, device=first.weight.device)
    trainable = [name for name in modules if name not in ("critic_target", *latent_modules(venv))]
    return parameter_counts(modules, trainable), architecture_summary(modules, examples)


def write_accounting(run: Run, agent: DBCAgent, venv: VecEnv) -> None:
    params, architecture = accounting(agent, venv)
    run.write_json(PARAMS_FILE, params)
    run.write_json(ARCHITECTURE_FILE, architecture)
