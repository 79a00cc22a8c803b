"""Offline phase of PL-LS (Algorithm 1, lines 2-3): train V_s or V_a on random-policy data.

``build(cfg, which, out)`` trains one model and writes every file of its artifact into ``out``;
only :func:`plls_bench.repr.store.ensure_artifact` calls it, under the artifact's file lock.
``new_model`` is the untrained architecture a config describes (the store loads weights into it).
"""
from __future__ import annotations

import io
import shutil
import time
from pathlib import Path

import numpy as np
import torch

from plls_bench.config import Config
from plls_bench.core.atomic_files import atomic_write_bytes, atomic_write_json
from plls_bench.core.signals import signals_deferred
from plls_bench.data import RandomPolicyData, get_dataset
from plls_bench.envs import make_env
from plls_bench.repr.fit import Split, batches, evaluate, fit, mean_reconstruction_mse, torch_threads
from plls_bench.repr.keys import FILES, model_config, repr_path, sha256, training_seed
from plls_bench.repr.models import VAE, ActionVAE, StateVAE
from plls_bench.repr.samples import action_samples, state_samples
from plls_bench.rundirs.artifacts import save_npz
from plls_bench.rundirs.devices import resolve_device


def action_dim(cfg: Config) -> int:
    """The task's action dimension, read from its env (cheap: no reset, no rendering)."""
    env = make_env(cfg.env, for_data=True)
    try:
        return int(np.prod(env.action_space.shape))
    finally:
        env.close()


def new_model(cfg: Config, which: str, n_actions: int | None = None) -> ActionVAE | StateVAE:
    """An untrained model with the config's architecture (``n_actions`` for V_a, else from the env)."""
    if which == "action":
        return ActionVAE(cfg.repr.action, n_actions if n_actions is not None else action_dim(cfg))
    return StateVAE(cfg.repr.state, cfg.env.image_size, precision=cfg.precision)


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
    final = repr_path(cfg, which)
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
    # contiguous: the stored weights do not depend on the layout the model ran in (plls_bench/repr/pixel_trunk.py)
    with signals_deferred():  # see plls_bench/core/signals.py: a signal inside torch.save fails the job
        torch.save({k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}, buffer)
    atomic_write_bytes(out / "model.pt", buffer.getvalue())
    atomic_write_json(out / "history.json", history)
    atomic_write_json(out / "test.json", test)
    save_npz(out / "samples.npz", samples)
