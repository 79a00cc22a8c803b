"""Offline phase of PL-LS (Algorithm 1, lines 2-3): train V_s and V_a on random-policy data.

``build`` trains one model into an artifact directory (see :mod:`plls_bench.repr.store`); the
runner ``repr`` makes sure the configured models exist and copies their metrics and samples into
its run, so a trial that reuses an artifact built by another still gets complete metrics.
"""
from __future__ import annotations

import io
import json
import logging
import shutil
import time
from pathlib import Path

import numpy as np
import torch

from plls_bench.artifacts import artifact_path, save_npz
from plls_bench.config import Config
from plls_bench.data import RandomPolicyData, get_dataset
from plls_bench.devices import resolve_device
from plls_bench.repr import get_action_vae, get_state_vae, new_model, training_seed
from plls_bench.repr.accounting import architecture_summary, parameter_counts
from plls_bench.repr.fit import Split, batches, evaluate, fit, mean_reconstruction_mse, torch_threads
from plls_bench.repr.models import VAE
from plls_bench.repr.samples import action_samples, state_samples
from plls_bench.repr.store import FILES, KINDS, ensure_artifact, model_config, repr_key, sha256
from plls_bench.runs import Run, atomic_write_bytes, atomic_write_json, read_json

log = logging.getLogger(__name__)


def splits(data: RandomPolicyData, which: str, val_fraction: float) -> tuple[Split, Split, Split]:
    """Train / validation / test: the dataset's test split, and the last ``val_fraction`` of
    its train split held out for validation (time-ordered, as the test split is)."""
    array, rows = (data.actions, np.arange(len(data))) if which == "action" else (data.observations, data.obs_index)
    train_rows, test_rows = rows[data.part("train")], rows[data.part("test")]
    n_val = int(round(len(train_rows) * val_fraction))
    if not 0 < n_val < len(train_rows):
        raise ValueError(f"a train split of {len(train_rows)} leaves no validation or no training data at "
                         f"repr.{which}.val_fraction={val_fraction}; collect more data")
    cut = len(train_rows) - n_val
    return Split(array, train_rows[:cut]), Split(array, train_rows[cut:]), Split(array, test_rows)


def _episode_steps(data: RandomPolicyData) -> np.ndarray:
    """Step of every transition within its episode, ``(N,)``."""
    first = np.searchsorted(data.episode, data.episode)  # episodes are stored contiguously
    return np.arange(len(data)) - first


def training_threads(cfg: Config, which: str) -> int:
    """Intra-op threads for training V_s or V_a. V_a's matmuls are tiny: a second thread only adds
    synchronisation, and on a busy 2-core machine it made epochs 10x slower (15 s vs 1.2 s). An
    explicit ``torch_threads`` wins."""
    return cfg.torch_threads or (1 if which == "action" else torch.get_num_threads())


def build(cfg: Config, which: str, out: Path) -> None:
    """Train ``cfg``'s ``which`` model and write every artifact file into ``out``."""
    began = time.perf_counter()
    mcfg, device = model_config(cfg, which), resolve_device(cfg.device)
    data, _ = get_dataset(cfg)
    train, val, test = splits(data, which, mcfg.val_fraction)
    seed = training_seed(cfg, which)
    final = artifact_path(cfg.runs_dir, KINDS[which], repr_key(cfg, which))
    resume = final.parent / f".{final.name}.partial" / "resume.pt"  # survives a kill; removed when done
    resume.parent.mkdir(parents=True, exist_ok=True)
    with torch.random.fork_rng(devices=[]), torch_threads(training_threads(cfg, which)):  # randomness stays in here
        torch.manual_seed(seed)
        model = new_model(cfg, which, data.actions.shape[1]).to(device)
        history = fit(model, train, val, epochs=cfg.budget.epochs_for(which), batch_size=mcfg.batch_size,
                      learning_rate=mcfg.learning_rate, seed=seed, device=device, resume=resume,
                      progress=cfg.progress, desc=f"V_{which[0]} ({cfg.env.name})")
        test_metrics = _test_metrics(model, test, mcfg.batch_size, device)
        samples = (action_samples(model, test, device) if which == "action" else
                   state_samples(model, test, _episode_steps(data)[data.part("test")], device))
    _write(out, model, history, samples, {
        **test_metrics, "n_train": len(train), "n_val": len(val), "n_test": len(test),
        "mean_predictor_mse": _mean_predictor_mse(train, test)})
    atomic_write_json(out / "meta.json", {
        "model": which, "key_hash": final.name, "sha256": {name: sha256(out / name) for name in FILES},
        "input_dim": int(data.actions.shape[1]) if which == "action" else list(data.observations.shape[1:]),
        "latent_dim": mcfg.latent_dim, "seed": seed, "device": str(device),
        "build_seconds": round(time.perf_counter() - began, 2)})
    shutil.rmtree(resume.parent, ignore_errors=True)


def _test_metrics(model: VAE, test: Split, batch_size: int, device: torch.device) -> dict[str, float]:
    metrics = {f"test_{k}": v for k, v in evaluate(model, test, batch_size, device).items()}
    # The paper's metric is taken to be the VAE's reconstruction with z sampled, as in Eqs. (2)-(3)
    # (so test_mse = test_recon_mse); decode(mu) is recorded beside it.
    metrics["test_mse"] = metrics["test_recon_mse"]
    metrics["test_mse_posterior_mean"] = mean_reconstruction_mse(model, test, batch_size, device)
    return metrics


def _mean_predictor_mse(train: Split, test: Split, chunk: int = 1000) -> float:
    """Per-element test MSE of predicting every test input by the training mean: the baseline
    a model that learned nothing (a collapsed posterior) would reach. Chunked: frames are big."""
    scale = 255.0 if train.array.dtype == np.uint8 else 1.0
    total = np.zeros(train.array.shape[1:], dtype=np.float64)
    for rows in batches(len(train), chunk):
        total += train.array[train.index[rows]].sum(axis=0, dtype=np.float64)
    mean = total / len(train) / scale
    squared = 0.0
    for rows in batches(len(test), chunk):
        squared += float(((test.array[test.index[rows]] / scale - mean) ** 2).sum())
    return squared / (len(test) * mean.size)


def _write(out: Path, model: VAE, history: list[dict], samples: dict[str, np.ndarray], test: dict) -> None:
    buffer = io.BytesIO()
    torch.save({k: v.detach().cpu() for k, v in model.state_dict().items()}, buffer)
    atomic_write_bytes(out / "model.pt", buffer.getvalue())
    atomic_write_json(out / "history.json", history)
    atomic_write_json(out / "test.json", test)
    save_npz(out / "samples.npz", samples)


def run(cfg: Config, run: Run) -> None:
    """Runner ``repr``: train (or reuse) every model the config turns on; write the README's
    ``metrics/repr_train.jsonl``, ``repr_test.json``, ``params.json``, ``architecture.json`` and
    ``samples/{state,action}_reconstructions.npz`` into the run."""
    rows, tests, modules, examples = [], {}, {}, {}
    for which, loader in (("state", get_state_vae), ("action", get_action_vae)):
        if model_config(cfg, which).kind != "vae":
            continue
        artifact = ensure_artifact(cfg, which)
        model = loader(cfg).requires_grad_(True)  # counted as trained here, in the offline phase
        rows += [{"model": which, **row} for row in read_json(artifact.path / "history.json")]
        tests[which] = {**read_json(artifact.path / "test.json"), "artifact": str(artifact.path),
                        "built_by_this_run": artifact.built}
        run.write_bytes(f"samples/{which}_reconstructions.npz", (artifact.path / "samples.npz").read_bytes())
        device = next(model.parameters()).device
        x = torch.zeros(1, *model.image_shape) if which == "state" else torch.zeros(1, model.action_dim)
        name = f"V_{which[0]}"  # V_s / V_a, as the paper and plls_bench.latent.latent_modules name them
        modules[f"{name}.encoder"], examples[f"{name}.encoder"] = model.encoder, x.to(device)
        modules[f"{name}.decoder"] = model.decoder
        examples[f"{name}.decoder"] = torch.zeros(1, model.latent_dim, device=device)
    run.write_bytes("metrics/repr_train.jsonl",
                    "".join(json.dumps(r, sort_keys=True) + "\n" for r in rows).encode())
    run.write_json("metrics/repr_test.json", tests)
    run.write_json("metrics/params.json", parameter_counts(modules, trainable=modules))
    run.write_json("metrics/architecture.json", architecture_summary(modules, examples))
    for which, metrics in tests.items():
        log.info("V_%s test MSE %.6g (mean predictor %.6g) from %s", which[0], metrics["test_mse"],
                 metrics["mean_predictor_mse"], metrics["artifact"])
