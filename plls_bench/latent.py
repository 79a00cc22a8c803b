"""STAND-IN until issue 3 (branch issue-3-repr) lands its latent wrappers; deleted at that merge.

Only ``repr.state.kind == repr.action.kind == "none"`` is supported here (plain PPO).
"""
from __future__ import annotations

from stable_baselines3.common.vec_env import VecEnv

from plls_bench.config import Config


def wrap_latent(venv: VecEnv, cfg: Config) -> VecEnv:
    if cfg.repr.state.kind == "none" and cfg.repr.action.kind == "none":
        return venv
    raise NotImplementedError("latent wrappers (V_s, V_a) come with issue 3: plls_bench/latent.py")


def latent_modules(venv: VecEnv) -> dict:
    """Stand-in: no latent wrappers, no frozen modules."""
    return {}
