"""Trained representations as content-addressed artifacts: key, build, verify, load.

An artifact (``<runs_dir>/artifacts/repr_{action,state}/<hash>/``) holds::

    model.pt       the state dict (tensors only; loaded with ``weights_only=True``)
    history.json   one row per epoch: train/val loss, recon MSE, KL (Figs. 6, 13, 15)
    test.json      test-split metrics; ``test_mse`` is the paper's metric
    samples.npz    reconstruction samples (Fig. 14 for V_s, Fig. 16 for V_a)
    meta.json      sizes, dims, build time and the sha256 of every file above
    key.json       what determines the content (written last by ``get_or_build``)

Every trial of a task shares one artifact, built once under a file lock.
"""
from __future__ import annotations

import hashlib
import logging
from dataclasses import asdict
from pathlib import Path
from typing import Any

import torch
from filelock import FileLock

from plls_bench.artifacts import Artifact, discard, get_or_build
from plls_bench.config import ActionReprConfig, Config, StateReprConfig
from plls_bench.runs import read_json

log = logging.getLogger(__name__)

REPR_FORMAT = 1  # bump when training or the stored layout changes: old artifacts are never reused
KINDS = {"action": "repr_action", "state": "repr_state"}
CONFIG_KEYS = {"action": "repr.action", "state": "repr.state"}
FILES = ("model.pt", "history.json", "test.json", "samples.npz")
# Settings used only at policy time: changing them must not retrain the VAE.
_NOT_IN_KEY = ("kind", "latent_action_bound")


class CheckpointError(ValueError):
    """A checkpoint cannot be loaded: unreadable, or not a state dict."""


class CheckpointMismatch(CheckpointError):
    """A stored checkpoint's tensors do not fit the model the config describes."""


def model_config(cfg: Config, which: str) -> ActionReprConfig | StateReprConfig:
    if which not in KINDS:
        raise ValueError(f"which must be 'action' or 'state', got {which!r}")
    return cfg.repr.action if which == "action" else cfg.repr.state


def repr_key(cfg: Config, which: str) -> dict[str, Any]:
    """Everything that determines a trained representation: data, architecture, training."""
    from plls_bench.data import dataset_key

    settings = {k: v for k, v in asdict(model_config(cfg, which)).items() if k not in _NOT_IN_KEY}
    from plls_bench.repr import training_seed

    return {"format": REPR_FORMAT, "model": which, "data": dataset_key(cfg), "repr": settings,
            "epochs": cfg.budget.epochs_for(which), "training_seed": training_seed(cfg, which)}


def sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def verify(path: Path) -> str | None:
    """None when every file matches the checksum in ``meta.json``, else what is wrong."""
    meta = read_json(path / "meta.json")
    if not isinstance(meta, dict) or not isinstance(meta.get("sha256"), dict):
        return "meta.json is missing or unreadable"
    for name in FILES:
        if not (path / name).is_file():
            return f"{name} is missing"
        if sha256(path / name) != meta["sha256"].get(name):
            return f"{name} does not match its checksum"
    return None


def ensure_artifact(cfg: Config, which: str) -> Artifact:
    """The verified artifact for ``cfg``'s ``which`` model, trained first if needed. A corrupt
    artifact (a file changed or torn since it was built) is discarded, logged and rebuilt."""
    from plls_bench.repr.train import build  # lazy: training imports the dataset and simulators

    key, kind = repr_key(cfg, which), KINDS[which]
    artifact = get_or_build(cfg.runs_dir, kind, key, lambda out: build(cfg, which, out))
    problem = verify(artifact.path)
    if problem is None:
        return artifact
    log.warning("discarding corrupt %s artifact %s (%s); rebuilding it", kind, artifact.path, problem)
    with FileLock(str(artifact.path) + ".lock"):
        if artifact.path.exists() and verify(artifact.path) is not None:
            discard(artifact.path)
    artifact = get_or_build(cfg.runs_dir, kind, key, lambda out: build(cfg, which, out))
    problem = verify(artifact.path)
    if problem is not None:
        raise RuntimeError(f"rebuilt {kind} artifact {artifact.path} fails verification: {problem}")
    return artifact


def load_weights(path: Path, model: torch.nn.Module, what: str) -> None:
    """Load the state dict at ``path`` into ``model`` after checking every name and shape.

    Nothing is copied unless everything fits, so a refused checkpoint never half-loads a model.
    ``what`` names the config section the model comes from, for the error message.
    """
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # torn zip, foreign pickle, anything weights_only refuses
        raise CheckpointError(f"{path} is not a readable checkpoint: {err}") from err
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise CheckpointError(f"{path} does not hold a state dict of tensors")
    expected = model.state_dict()
    problems = [f"{name}: checkpoint {list(state[name].shape)}, {what} gives {list(tensor.shape)}"
                for name, tensor in expected.items()
                if name in state and tuple(state[name].shape) != tuple(tensor.shape)]
    problems += [f"{name}: missing from the checkpoint" for name in expected if name not in state]
    problems += [f"{name}: in the checkpoint, not in the model {what} describes"
                 for name in state if name not in expected]
    if problems:
        raise CheckpointMismatch(f"checkpoint {path} does not match the config ({what}): "
                                 + "; ".join(problems))
    model.load_state_dict(state)
