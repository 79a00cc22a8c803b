"""Trained representations as content-addressed artifacts: verify, get-or-build, load.

An artifact (``<runs_dir>/artifacts/repr_{action,state}/<hash>/``, ``hash`` from
:func:`plls_bench.repr.keys.repr_key`) holds::

    model.pt       the state dict (tensors only; loaded with ``weights_only=True``)
    history.json   one row per epoch: train/val loss, recon MSE, KL (Figs. 6, 13, 15)
    test.json      test-split metrics; ``test_mse`` is the paper's metric
    samples.npz    reconstruction samples (Fig. 14 for V_s, Fig. 16 for V_a)
    meta.json      sizes, dims, build time and the sha256 of every file above
    key.json       what determines the content (written last by ``get_or_build``)

Every trial of a task shares one artifact, built once under a file lock. Two entry points:

- :func:`ensure_representations` for a runner's setup (``ppo``, ``dbc``, ``study``, ``repr``):
  builds what is missing, loads every model the config uses once, logs the artifact keys;
- :func:`load_representations` for what only reads (filmstrips, ``load_trained``, bench scripts):
  never trains; a missing artifact raises :class:`MissingArtifact` naming its key and the
  command that builds it.
"""
from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import torch
from filelock import FileLock

from plls_bench.config import Config
from plls_bench.core.atomic_files import read_json
from plls_bench.core.seeding import quiet_rng
from plls_bench.repr.keys import (
    CONFIG_KEYS,
    FILES,
    KINDS,
    NAMES,
    build_command,
    model_config,
    repr_key,
    repr_path,
    sha256,
)
from plls_bench.repr.models import ActionVAE, StateVAE
from plls_bench.repr.train import build, new_model
from plls_bench.rundirs.artifacts import Artifact, discard, get_or_build, is_built
from plls_bench.rundirs.devices import resolve_device
from plls_bench.rundirs.record_layout import recorded_artifact
from plls_bench.rundirs.record_restore import copy_artifact_files

log = logging.getLogger(__name__)


class CheckpointError(ValueError):
    """A checkpoint cannot be loaded: unreadable, or not a state dict."""


class CheckpointMismatch(CheckpointError):
    """A stored checkpoint's tensors do not fit the model the config describes."""


class MissingArtifact(FileNotFoundError):
    """A load-only caller asked for an artifact that is not built (or no longer verifies)."""


@dataclass(frozen=True)
class Representations:
    """The frozen V_s / V_a a config uses, loaded once (None where ``repr.*.kind`` is ``none``).

    ``action_bound`` is ``repr.action.latent_action_bound`` (the policy's latent action box);
    ``artifacts`` maps ``state`` / ``action`` to the artifact each model was loaded from.
    """

    state_vae: StateVAE | None = None
    action_vae: ActionVAE | None = None
    action_bound: float = 0.0
    artifacts: Mapping[str, Artifact] = field(default_factory=dict)

    def check(self, cfg: Config) -> Representations:
        """``self``, once it holds exactly the models ``cfg`` turns on: an env built from a PL-LS
        config without its models would silently act in the raw spaces."""
        for which, model in (("state", self.state_vae), ("action", self.action_vae)):
            wanted = model_config(cfg, which).kind == "vae"
            if wanted != (model is not None):
                raise ValueError(f"{CONFIG_KEYS[which]}.kind is {model_config(cfg, which).kind!r} but "
                                 f"{NAMES[which]} is {'not ' if wanted else ''}among the representations "
                                 f"given: pass ensure_representations(cfg) or load_representations(cfg)")
        return self


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


def _require_vae(cfg: Config, which: str) -> None:
    kind = model_config(cfg, which).kind
    if kind != "vae":
        raise ValueError(f"{CONFIG_KEYS[which]}.kind is {kind!r}: set repr/{which}=vae to get {NAMES[which]}")


def ensure_artifact(cfg: Config, which: str) -> Artifact:
    """The verified artifact for ``cfg``'s ``which`` model, trained first if needed. A corrupt
    artifact (a file changed or torn since it was built) is discarded, logged and rebuilt."""
    _require_vae(cfg, which)
    restore_recorded(cfg, which)
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


def find_artifact(cfg: Config, which: str) -> Artifact:
    """The verified artifact for ``cfg``'s ``which`` model, never built here: a missing or
    corrupt one raises :class:`MissingArtifact` naming its key and the command that builds it."""
    _require_vae(cfg, which)
    restore_recorded(cfg, which)
    path = repr_path(cfg, which)
    if not is_built(cfg.runs_dir, KINDS[which], repr_key(cfg, which)):
        raise MissingArtifact(f"{NAMES[which]} artifact {KINDS[which]}/{path.name} is missing (no {path}): "
                              f"run `{build_command(cfg, which)}` first")
    problem = verify(path)
    if problem is not None:
        raise MissingArtifact(f"{NAMES[which]} artifact {KINDS[which]}/{path.name} at {path} is corrupt "
                              f"({problem}): run `{build_command(cfg, which)}` to rebuild it")
    return Artifact(path, built=False)


def restore_recorded(cfg: Config, which: str) -> None:
    """Copy the committed record of ``cfg``'s ``which`` artifact (``records/artifacts/``, beside
    the runs dir) into the runs dir when it is not built there: no training, no dataset."""
    kind, key = KINDS[which], repr_key(cfg, which)
    source = recorded_artifact(cfg.runs_dir, kind, repr_path(cfg, which).name)
    if source is None or is_built(cfg.runs_dir, kind, key):
        return
    problem = verify(source)
    if problem is not None:
        log.warning("recorded %s artifact %s is not usable (%s); building it instead", kind, source, problem)
        return
    if get_or_build(cfg.runs_dir, kind, key, lambda out: copy_artifact_files(source, out)).built:
        log.info("%s artifact %s/%s restored from record %s", NAMES[which], kind, source.name, source)


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


def load_model(cfg: Config, which: str, artifact: Artifact) -> ActionVAE | StateVAE:
    """The artifact's model: frozen, in eval mode, on ``cfg.device``. V_a's input size comes from
    the artifact's ``meta.json``, so loading never builds the task's env."""
    meta = read_json(artifact.path / "meta.json") or {}
    n_actions = int(meta["input_dim"]) if which == "action" and "input_dim" in meta else None
    with quiet_rng():  # the throw-away initial weights never draw from the global stream
        model = new_model(cfg, which, n_actions)
    load_weights(artifact.path / "model.pt", model, CONFIG_KEYS[which])
    return model.to(resolve_device(cfg.device)).eval().requires_grad_(False)


def ensure_representations(cfg: Config) -> Representations:
    """Every representation ``cfg`` uses, built first where missing (under the artifact's file
    lock, as every trial shares it) and loaded once. A runner's one representation step."""
    return _representations(cfg, ensure_artifact)


def load_representations(cfg: Config) -> Representations:
    """Every representation ``cfg`` uses, loaded; never trains (raises :class:`MissingArtifact`)."""
    return _representations(cfg, find_artifact)


def _representations(cfg: Config, lookup: Callable[[Config, str], Artifact]) -> Representations:
    models: dict[str, ActionVAE | StateVAE] = {}
    artifacts: dict[str, Artifact] = {}
    for which in ("state", "action"):
        if model_config(cfg, which).kind != "vae":
            continue
        artifacts[which] = lookup(cfg, which)
        models[which] = load_model(cfg, which, artifacts[which])
        log.info("%s artifact %s/%s %s, loaded from %s", NAMES[which], KINDS[which], artifacts[which].path.name,
                 "built" if artifacts[which].built else "found", artifacts[which].path)
    state, action = models.get("state"), models.get("action")
    assert state is None or isinstance(state, StateVAE)
    assert action is None or isinstance(action, ActionVAE)
    return Representations(state, action, cfg.repr.action.latent_action_bound, artifacts)
