"""Random-policy datasets: content-addressed artifacts shared by all trials of a task.

Layer ``tasks`` of tests/test_imports.py: imports only from itself and the layers below it
(``core`` up to ``run dirs``); no layer below imports it.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from plls_bench.config import Config
from plls_bench.config.tasks import RESTYLED_TASKS
from plls_bench.core.atomic_files import atomic_write_json, read_json
from plls_bench.core.seeding import derive_seeds
from plls_bench.rundirs.artifacts import Artifact, get_or_build, load_npz, save_npz
from plls_bench.rundirs.run_dir import Run

DATA_FORMAT = 1  # bump when the stored layout changes: old artifacts are then never reused
# Env settings that do not change the collected data (parallelism) stay out of the key.
_NOT_IN_KEY = ("data_num_envs", "data_async", "pixels", "backend_threads")


@dataclass
class RandomPolicyData:
    """A random-policy dataset; transitions ``[0, n_train)`` are train, the rest test.

    Shapes (N transitions, E episodes, A action dims, O observation shape)::

        observations (N + E, *O)  s_t of every step plus each episode's final observation
        actions (N, A) float32, rewards (N,) float32, terminated (N,) bool, truncated (N,) bool
        episode (N,) int32        episode index of each transition
        obs_index (N,) int64      observations[obs_index[i]] = s_i, observations[obs_index[i]+1] = s'_i
    """

    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    episode: np.ndarray
    obs_index: np.ndarray
    n_train: int

    def __len__(self) -> int:
        return len(self.actions)

    def part(self, name: str) -> slice:
        """Transition indices of the ``train`` or ``test`` split (time-ordered: test is last)."""
        if name not in ("train", "test"):
            raise ValueError(f"split must be 'train' or 'test', got {name!r}")
        return slice(0, self.n_train) if name == "train" else slice(self.n_train, len(self))

    def states(self, name: str) -> np.ndarray:
        """s_t of the split's transitions, ``(n, *O)``."""
        return self.observations[self.obs_index[self.part(name)]]

    def action_split(self, name: str) -> np.ndarray:
        """Actions of the split, ``(n, A)``."""
        return self.actions[self.part(name)]


def dataset_key(cfg: Config) -> dict[str, Any]:
    """Everything that determines a dataset's content."""
    env = {k: v for k, v in asdict(cfg.env).items() if k not in _NOT_IN_KEY}
    if env["backend"] == "gymnasium":  # the backend before the key existed: old artifacts keep their keys
        del env["backend"]
    if env["name"] not in RESTYLED_TASKS:  # env.visuals restyles dm_control only: it cannot change
        del env["visuals"]  # this task's data, and the artifacts made before the key exist keep their keys
    seeds = derive_seeds(cfg.seed, cfg.data_seed, cfg.repr.per_trial)
    return {"format": DATA_FORMAT, "env": env, "episodes": cfg.budget.data_episodes,
            "max_steps": cfg.budget.data_steps_per_episode, "seed": seeds.data}


def _build(cfg: Config, out: Path) -> None:
    from plls_bench.data.collect import collect_random_policy  # lazy: imports the simulators

    start = time.perf_counter()
    key = dataset_key(cfg)
    arrays = collect_random_policy(cfg.env, key["episodes"], key["max_steps"], key["seed"], cfg.progress)
    n = len(arrays["actions"])
    n_train = int(round(n * cfg.env.data_train_fraction))
    if not 0 < n_train < n:
        raise ValueError(f"dataset of {n} transitions leaves an empty split at "
                         f"env.data_train_fraction={cfg.env.data_train_fraction}; collect more data")
    save_npz(out / "data.npz", arrays)
    returns = np.bincount(arrays["episode"], weights=arrays["rewards"])
    atomic_write_json(out / "meta.json", {
        "task": cfg.env.name, "transitions": n, "episodes": int(arrays["episode"].max()) + 1,
        "n_train": n_train, "n_test": n - n_train,
        "observation_shape": list(arrays["observations"].shape[1:]),
        "observation_dtype": str(arrays["observations"].dtype),
        "episode_return_mean": float(returns.mean()), "episode_return_std": float(returns.std()),
        "build_seconds": round(time.perf_counter() - start, 2),
    })


def get_dataset(cfg: Config) -> tuple[RandomPolicyData, Artifact]:
    """The task's random-policy dataset, collected on first use and shared afterwards."""
    artifact = get_or_build(cfg.runs_dir, "data", dataset_key(cfg), lambda out: _build(cfg, out))
    return load_dataset(artifact.path), artifact


def load_dataset(path: Path) -> RandomPolicyData:
    meta = read_json(path / "meta.json")
    if meta is None:
        raise FileNotFoundError(f"{path}/meta.json is missing or unreadable")
    return RandomPolicyData(**load_npz(path / "data.npz"), n_train=int(meta["n_train"]))


def run(cfg: Config, run: Run) -> None:
    """Runner ``collect``: build (or reuse) the dataset and record its summary in the run."""
    _, artifact = get_dataset(cfg)
    meta = read_json(artifact.path / "meta.json") or {}
    run.write_json("metrics/dataset.json", {**meta, "artifact": str(artifact.path),
                                            "built_by_this_run": artifact.built})
