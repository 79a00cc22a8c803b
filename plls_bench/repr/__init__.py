"""The learned representations of PL-LS: V_s (state VAE) and V_a (action VAE).

``get_state_vae(cfg)`` / ``get_action_vae(cfg)`` return the trained model for the config's task,
representation settings and data seed: frozen, in eval mode, on ``cfg.device``. The first call
trains it as a content-addressed artifact shared by every trial (see :mod:`.store`).
"""
from __future__ import annotations

import numpy as np

from plls_bench.config import Config
from plls_bench.devices import resolve_device
from plls_bench.repr.models import ActionVAE, StateVAE
from plls_bench.seeding import derive_seeds

__all__ = ["ActionVAE", "StateVAE", "get_action_vae", "get_state_vae"]

_STREAMS = {"state": 0, "action": 1}  # independent training streams off the data seed


def training_seed(cfg: Config, which: str) -> int:
    """Seed of a model's initialisation, shuffling and noise. Derived from the data stream, so a
    representation is fixed by (task, repr config, data seed) and shared by all trials; with
    ``repr.per_trial_training`` also from the trial seed (trial 0 gets the shared model's seed)."""
    data_seed = derive_seeds(cfg.seed, cfg.data_seed, cfg.repr.per_trial).data
    model_trial = cfg.seed if cfg.repr.per_trial_training else 0
    return int(np.random.SeedSequence([data_seed, _STREAMS[which], model_trial]).generate_state(1)[0])


def action_dim(cfg: Config) -> int:
    """The task's action dimension, read from its env (cheap: no reset, no rendering)."""
    from plls_bench.envs import make_env

    env = make_env(cfg.env, for_data=True)
    try:
        return int(np.prod(env.action_space.shape))
    finally:
        env.close()


def new_model(cfg: Config, which: str, n_actions: int | None = None) -> ActionVAE | StateVAE:
    """An untrained model with the config's architecture (``n_actions`` for V_a, else from the env)."""
    if which == "action":
        return ActionVAE(cfg.repr.action, n_actions if n_actions is not None else action_dim(cfg))
    return StateVAE(cfg.repr.state, cfg.env.image_size)


def _load(cfg: Config, which: str) -> ActionVAE | StateVAE:
    from plls_bench.repr.store import CONFIG_KEYS, ensure_artifact, load_weights

    if getattr(cfg.repr, which).kind != "vae":
        raise ValueError(f"{CONFIG_KEYS[which]}.kind is {getattr(cfg.repr, which).kind!r}: "
                         f"set repr/{which}=vae to get V_{which[0]}")
    artifact = ensure_artifact(cfg, which)
    model = new_model(cfg, which)
    load_weights(artifact.path / "model.pt", model, CONFIG_KEYS[which])
    return model.to(resolve_device(cfg.device)).eval().requires_grad_(False)


def get_action_vae(cfg: Config) -> ActionVAE:
    """The trained, frozen V_a for ``cfg`` (trained and stored on first use)."""
    model = _load(cfg, "action")
    assert isinstance(model, ActionVAE)
    return model


def get_state_vae(cfg: Config) -> StateVAE:
    """The trained, frozen V_s for ``cfg`` (trained and stored on first use)."""
    model = _load(cfg, "state")
    assert isinstance(model, StateVAE)
    return model
