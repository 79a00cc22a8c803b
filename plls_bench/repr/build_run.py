"""Runner ``repr``: the offline phase of PL-LS (Algorithm 1, lines 2-3) as a run.

It makes sure every model the config turns on exists (:func:`.store.ensure_representations`
builds what is missing) and copies each artifact's metrics and samples into the run, so a trial
that reuses an artifact built by another still gets complete metrics.
"""
from __future__ import annotations

import logging

import torch

from plls_bench.config import Config
from plls_bench.core.atomic_files import read_json
from plls_bench.repr.accounting import architecture_summary, parameter_counts
from plls_bench.repr.keys import NAMES
from plls_bench.repr.store import Representations, ensure_representations
from plls_bench.rundirs.run_dir import ARCHITECTURE_FILE, PARAMS_FILE, Run

log = logging.getLogger(__name__)


def run(cfg: Config, run: Run) -> None:
    """Runner ``repr``: train (or reuse) every model the config turns on; write docs/architecture.md's
    ``metrics/repr_train.jsonl``, ``repr_test.json``, ``params.json``, ``architecture.json`` and
    ``samples/{state,action}_reconstructions.npz`` into the run."""
    reprs = ensure_representations(cfg)
    rows, modules, examples = [], {}, {}
    for which, model in (("state", reprs.state_vae), ("action", reprs.action_vae)):
        if model is None:
            continue
        artifact = reprs.artifacts[which]
        model.requires_grad_(True)  # counted as trained here, in the offline phase
        rows += [{"model": which, **row} for row in read_json(artifact.path / "history.json")]
        run.write_bytes(f"samples/{which}_reconstructions.npz", (artifact.path / "samples.npz").read_bytes())
        device = next(model.parameters()).device
        x = torch.zeros(1, *model.image_shape) if which == "state" else torch.zeros(1, model.action_dim)
        name = NAMES[which]  # V_s / V_a, as plls_bench.repr.latent_wrappers.latent_modules names them
        modules[f"{name}.encoder"], examples[f"{name}.encoder"] = model.encoder, x.to(device)
        modules[f"{name}.decoder"] = model.decoder
        examples[f"{name}.decoder"] = torch.zeros(1, model.latent_dim, device=device)
    run.write_metrics("repr_train", rows)
    run.write_json("metrics/repr_test.json", model_test_metrics(reprs))
    run.write_json(PARAMS_FILE, parameter_counts(modules, trainable=modules))
    run.write_json(ARCHITECTURE_FILE, architecture_summary(modules, examples))
    for which, metrics in model_test_metrics(reprs).items():
        log.info("%s test MSE %.6g (mean predictor %.6g) from %s", NAMES[which], metrics["test_mse"],
                 metrics["mean_predictor_mse"], metrics["artifact"])


def model_test_metrics(reprs: Representations) -> dict[str, dict]:
    """``metrics/repr_test.json``: per model (``state`` / ``action``) its artifact's test metrics,
    the artifact's path and whether this run built it. Runners that train a policy on the models
    write it too, so a sweep over a model's settings finds each model's MSE in its own runs."""
    return {which: {**read_json(artifact.path / "test.json"), "artifact": str(artifact.path),
                    "built_by_this_run": artifact.built} for which, artifact in reprs.artifacts.items()}
