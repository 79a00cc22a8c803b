"""Explicit seeding: one trial seed derives every stream of randomness through SeedSequence.

Representations are shared by all trials (the paper's offline phase), so the data stream comes
from ``data_seed`` unless ``repr.per_trial`` asks for one per trial.
"""
from __future__ import annotations

import random
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import torch

# Spawn keys name the streams, so adding a stream later never shifts the existing ones.
_DATA, _TRAIN, _EVAL = 0, 1, 2


@dataclass(frozen=True)
class Seeds:
    data: int   # random-policy collection and representation training
    train: int  # policy learning: network init, sampling, training env resets
    eval: int   # evaluation envs (separately seeded, never used for learning)


def derive_seeds(seed: int, data_seed: int, per_trial_data: bool = False) -> Seeds:
    """Seeds of every stream for trial ``seed``."""
    return Seeds(
        data=sub_seed(seed if per_trial_data else data_seed, _DATA),
        train=sub_seed(seed, _TRAIN),
        eval=sub_seed(seed, _EVAL),
    )


def episode_seeds(seed: int, n: int) -> list[int]:
    """``n`` independent seeds for episodes 0..n-1 of a stream seeded by ``seed``."""
    return [sub_seed(seed, i) for i in range(n)]  # = SeedSequence(seed).spawn(n), child i's first word


def seed_everything(seed: int) -> None:
    """Seed python, numpy's legacy global RNG and torch (for libraries that use them)."""
    random.seed(seed)
    np.random.seed(seed % 2**32)
    try:
        import torch
    except ImportError:
        return
    torch.manual_seed(seed)


@contextmanager
def quiet_rng(device: str | torch.device = "cpu") -> Iterator[None]:
    """Run the block on a fork of torch's global RNG, restored on exit: building a module only to
    load weights into it (V_s, V_a, a trained policy) draws its throw-away initial weights here,
    so how often anything was loaded never shifts the training stream seeded by the runner.
    ``device`` adds its CUDA generator to the fork when it is a GPU; the CPU one is always forked."""
    import torch

    where = torch.device(device)
    cuda = where.type == "cuda" and torch.cuda.is_available()
    devices = [where.index if where.index is not None else torch.cuda.current_device()] if cuda else []
    with torch.random.fork_rng(devices=devices):
        yield


def derived_seed(entropy: int | tuple[int, ...], spawn_key: tuple[int, ...] = ()) -> int:
    """The one derivation of a seed: the first uint32 word of ``SeedSequence(entropy, spawn_key)``.

    Two forms are in use, and both stay, since recorded runs and artifact keys hold their numbers:
    a sub-stream of one seed (``spawn_key``: :func:`sub_seed`) and a seed mixed from a tuple of
    numbers given as ``entropy`` (DBC's env seeds per resume and per evaluation, V_s / V_a training
    seeds). tests/test_seeding.py pins values of each."""
    seq = np.random.SeedSequence(entropy=entropy, spawn_key=spawn_key)
    return int(seq.generate_state(1, dtype=np.uint32)[0])


def sub_seed(seed: int, *key: int) -> int:
    """A seed for the sub-stream ``key`` of a stream seeded by ``seed`` (e.g. the training envs'
    resets after a resume at iteration k: ``sub_seed(train, k)``)."""
    return derived_seed(seed, tuple(key))
