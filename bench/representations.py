"""Shared by the bench scripts: the tiny V_s / V_a that speed measurements use, built visibly.

Representations in the RL presets come from a tiny dataset and one epoch: their weights do not
change the speed of acting or updating, and a quick-budget V_s would take longer than the bench.
"""
from __future__ import annotations

from plls_bench.config import Config

TINY_REPR = ("budget.data_episodes=2", "budget.data_steps_per_episode=100", "budget.repr_epochs=1",
             "budget.repr_action_epochs=1")


def prepare_representations(cfg: Config) -> None:
    """This script's one training step, before any timing: build (or reuse) the V_s / V_a that
    ``cfg`` uses, so the measurements below load them and never train."""
    from plls_bench.repr.store import ensure_representations

    if "vae" in (cfg.repr.state.kind, cfg.repr.action.kind):
        print(f"building (or reusing) the representations of {cfg.experiment} under {cfg.runs_dir}", flush=True)
        ensure_representations(cfg)
