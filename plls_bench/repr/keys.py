"""What identifies a trained representation: its key, the key's hash, the artifact's files and
the ``runner=repr`` preset that builds it.

Nothing here trains or loads anything (no torch): the planner and the store both read keys.
"""
from __future__ import annotations

import hashlib
from dataclasses import asdict
from pathlib import Path
from typing import Any

from plls_bench.config import ActionReprConfig, Config, ConfigError, StateReprConfig
from plls_bench.core.seeding import derive_seeds, derived_seed
from plls_bench.data import dataset_key
from plls_bench.rundirs.artifacts import artifact_path
from plls_bench.rundirs.composition import CONF_DIR, compose

REPR_FORMAT = 1  # bump when training or the stored layout changes: old artifacts are never reused
KINDS = {"action": "repr_action", "state": "repr_state"}
CONFIG_KEYS = {"action": "repr.action", "state": "repr.state"}
NAMES = {"action": "V_a", "state": "V_s"}  # as the paper and the summaries name them
FILES = ("model.pt", "history.json", "test.json", "samples.npz")
# Settings used only at policy time: changing them must not retrain the VAE.
_NOT_IN_KEY = ("kind", "latent_action_bound")
_STREAMS = {"state": 0, "action": 1}  # independent training streams off the data seed


def model_config(cfg: Config, which: str) -> ActionReprConfig | StateReprConfig:
    """``cfg.repr.action`` or ``cfg.repr.state``."""
    if which not in KINDS:
        raise ValueError(f"which must be 'action' or 'state', got {which!r}")
    return cfg.repr.action if which == "action" else cfg.repr.state


def training_seed(cfg: Config, which: str) -> int:
    """Seed of a model's initialisation, shuffling and noise. Derived from the data stream, so a
    representation is fixed by (task, repr config, data seed) and shared by all trials; with
    ``repr.per_trial_training`` also from the trial seed (trial 0 gets the shared model's seed)."""
    data_seed = derive_seeds(cfg.seed, cfg.data_seed, cfg.repr.per_trial).data
    model_trial = cfg.seed if cfg.repr.per_trial_training else 0
    return derived_seed((data_seed, _STREAMS[which], model_trial))


def repr_key(cfg: Config, which: str) -> dict[str, Any]:
    """Everything that determines a trained representation: data, architecture, training."""
    settings = {k: v for k, v in asdict(model_config(cfg, which)).items() if k not in _NOT_IN_KEY}
    key = {"format": REPR_FORMAT, "model": which, "data": dataset_key(cfg), "repr": settings,
           "epochs": cfg.budget.epochs_for(which), "training_seed": training_seed(cfg, which)}
    return {**key, **_precision(cfg, which)}


def _precision(cfg: Config, which: str) -> dict[str, str]:
    """V_s's conv trunks train in ``cfg.precision``; a bf16 V_s is another artifact. fp32 (all
    artifacts before the key) stays out of the key, so theirs are unchanged; V_a has no conv trunk."""
    return {"precision": cfg.precision} if which == "state" and cfg.precision != "fp32" else {}


def repr_path(cfg: Config, which: str) -> Path:
    """Where ``cfg``'s ``which`` artifact lives (or will): ``<runs_dir>/artifacts/repr_*/<hash>``."""
    return artifact_path(cfg.runs_dir, KINDS[which], repr_key(cfg, which))


def sha256(path: Path) -> str:
    """Hex digest of a file's bytes, read in 1 MiB chunks: never a whole model in memory."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def build_command(cfg: Config, which: str) -> str:
    """The command that builds ``cfg``'s ``which`` artifact: the task's V_s / V_a preset
    (``carracing_vs``, ``mountaincar_va``, ...) with the budget, runs_dir and seeds that give the
    same key. When the preset's defaults still give another key (``repr.*`` overrides), says so."""
    preset = f"{cfg.env.name}_v{which[0]}"
    if (CONF_DIR / "experiment" / f"{preset}.yaml").is_file():
        args = [f"+experiment={preset}"]
    else:
        args = ["runner=repr", "algo=none", f"env={cfg.env.name}", f"repr/{which}=vae"]
    args += [f"budget={cfg.budget.name}", f"runs_dir={cfg.runs_dir}"]
    args += [f"data_seed={cfg.data_seed}"] if cfg.data_seed else []
    args += ["repr.per_trial=true"] if cfg.repr.per_trial else []
    args += [f"precision={cfg.precision}"] if _precision(cfg, which) else []
    if cfg.seed and (cfg.repr.per_trial or cfg.repr.per_trial_training):
        args.append(f"seed={cfg.seed}")  # the seed is part of the key then
    command = "python -m plls_bench " + " ".join(args)
    try:  # the hint is checked, not guessed: compose it and compare keys
        same = repr_key(compose(args), which) == repr_key(cfg, which)
    except ConfigError:
        same = False
    return command if same else f"{command} with this config's other {CONFIG_KEYS[which]}.* / budget.* overrides"
