"""Minibatch training of a VAE on one split of a random-policy dataset, resumable per epoch.

Data stay in the dataset's arrays; a :class:`Split` is an index array into them, so CarRacing
frames (uint8, ``(N, 3, 96, 96)``) are converted to float in [0, 1] one batch at a time.
"""
from __future__ import annotations

import io
import logging
import time
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from plls_bench.core.atomic_files import atomic_write_bytes
from plls_bench.core.progress_bars import progress_bar
from plls_bench.core.signals import signals_deferred
from plls_bench.repr.models import VAE
from plls_bench.repr.pixel_trunk import pixels_to_unit

log = logging.getLogger(__name__)


@dataclass
class Split:
    """Rows ``index`` of ``array`` (``(N, *shape)``: float32 actions or uint8 frames)."""

    array: np.ndarray
    index: np.ndarray

    def __len__(self) -> int:
        return len(self.index)

    def batch(self, rows: np.ndarray, device: torch.device) -> Tensor:
        """Rows ``rows`` of the split as float32, uint8 pixels scaled to [0, 1]."""
        return pixels_to_unit(torch.as_tensor(self.array[self.index[rows]], device=device))


@contextmanager
def torch_threads(n: int) -> Iterator[None]:
    """Run the block with ``n`` torch intra-op threads, then restore the previous count."""
    previous = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def batches(n: int, size: int, order: np.ndarray | None = None) -> Iterator[np.ndarray]:
    """Consecutive chunks of ``order`` (default ``arange(n)``) of at most ``size`` rows."""
    order = np.arange(n) if order is None else order
    for start in range(0, n, size):
        yield order[start:start + size]


@torch.no_grad()
def evaluate(model: VAE, split: Split, batch_size: int, device: torch.device) -> dict[str, float]:
    """Batch-size-weighted means of ``loss``, ``recon_mse`` and ``kl`` (z sampled, as in training)."""
    model.eval()
    sums: dict[str, float] = defaultdict(float)
    for rows in batches(len(split), batch_size):
        for name, value in model.loss(split.batch(rows, device)).items():
            sums[name] += float(value) * len(rows)
    return {name: total / len(split) for name, total in sums.items()}


@torch.no_grad()
def reconstruct(model: VAE, x: Tensor, sample: bool) -> Tensor:
    """The VAE's reconstruction of ``x``: decode(mu + std * eps) with ``sample`` (the forward pass of
    Eqs. (2)-(3), what ``test_mse`` measures), else decode(mu) at the posterior mean."""
    model.eval()
    if sample:
        return model(x)[0]
    return model.decode(model.encode(x)[0])


@torch.no_grad()
def mean_reconstruction_mse(model: VAE, split: Split, batch_size: int, device: torch.device) -> float:
    """Per-element MSE of decode(mu(x)), the posterior-mean reconstruction, over the whole split."""
    total, count = 0.0, 0
    for rows in batches(len(split), batch_size):
        x = split.batch(rows, device)
        total += float((reconstruct(model, x, sample=False) - x).pow(2).sum())
        count += x.numel()
    return total / count


def _save_resume(path: Path, model: VAE, optimizer: torch.optim.Optimizer, epoch: int,
                 history: list[dict[str, float]]) -> None:
    buffer = io.BytesIO()
    with signals_deferred():  # a requeue or stop signal inside torch.save would fail the job instead
        torch.save({"model": model.state_dict(), "optimizer": optimizer.state_dict(), "epoch": epoch,
                    "rng": torch.get_rng_state(), "history": history}, buffer)
    atomic_write_bytes(path, buffer.getvalue())


def _load_resume(path: Path, model: VAE, optimizer: torch.optim.Optimizer) -> tuple[int, list]:
    """Restore training from ``path``; a missing or unreadable file starts from epoch 0."""
    if not path.exists():
        return 0, []
    fresh = {k: v.clone() for k, v in model.state_dict().items()}
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        torch.set_rng_state(state["rng"])
    except Exception as err:  # a torn or foreign file: training restarts, nothing is trusted
        log.warning("ignoring unreadable resume state %s (%s): training from scratch", path, err)
        model.load_state_dict(fresh)  # undo whatever part of the state did load
        optimizer.state.clear()
        return 0, []
    log.info("resuming VAE training from %s after epoch %d", path, state["epoch"])
    return int(state["epoch"]), list(state["history"])


def fit(model: VAE, train: Split, val: Split, *, epochs: int, batch_size: int, learning_rate: float,
        seed: int, device: torch.device, resume: Path, progress: bool, desc: str) -> list[dict[str, float]]:
    """Adam on the negative ELBO for ``epochs`` epochs; one history row per epoch.

    After every epoch the model, optimizer, torch RNG and history go to ``resume`` (atomically),
    so a killed build continues where it stopped and ends with the same weights. Epoch e's
    shuffle comes from ``(seed, e)``; the caller seeds torch's RNG (init and eps).
    """
    optimizer = torch.optim.Adam(model.parameters(), lr=learning_rate)
    start, history = _load_resume(resume, model, optimizer)
    steps_per_epoch = -(-len(train) // batch_size)
    with progress_bar(total=epochs * steps_per_epoch, initial=start * steps_per_epoch, desc=desc,
              unit="batch", disable=not progress) as bar:
        for epoch in range(start + 1, epochs + 1):
            began = time.perf_counter()
            model.train()
            sums: dict[str, float] = defaultdict(float)
            order = np.random.default_rng([seed, epoch]).permutation(len(train))
            for rows in batches(len(train), batch_size, order):
                terms = model.loss(train.batch(rows, device))
                optimizer.zero_grad(set_to_none=True)
                terms["loss"].backward()
                optimizer.step()
                for name, value in terms.items():
                    sums[name] += float(value.detach()) * len(rows)
                bar.update(1)
                bar.set_postfix(epoch=epoch, loss=f"{float(terms['loss'].detach()):.4g}")
            row = {"epoch": epoch, **{f"train_{k}": v / len(train) for k, v in sums.items()},
                   **{f"val_{k}": v for k, v in evaluate(model, val, batch_size, device).items()},
                   "epoch_seconds": round(time.perf_counter() - began, 3)}
            history.append(row)
            _save_resume(resume, model, optimizer, epoch, history)
    return history
