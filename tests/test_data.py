"""Random-policy data: deterministic bytes, paper-sized splits, built once across processes."""
from __future__ import annotations

import hashlib
import multiprocessing as mp
from pathlib import Path

import numpy as np
import pytest

from plls_bench.data import get_dataset
from plls_bench.rundirs.composition import compose
from tests.conftest import compose_preset, in_two_processes


def data_bytes(path: Path) -> str:
    return hashlib.sha256((path / "data.npz").read_bytes()).hexdigest()


@pytest.mark.parametrize("task", ["mountaincar", "carracing", "cheetah"])
def test_same_seed_gives_byte_identical_data(task: str, tmp_path: Path) -> None:
    digests = []
    for attempt in ("a", "b"):
        cfg = compose_preset(None, tmp_path / attempt, f"env={task}")
        data, artifact = get_dataset(cfg)
        assert artifact.built
        digests.append(data_bytes(artifact.path))
    assert digests[0] == digests[1]
    steps = cfg.budget.data_steps_per_episode
    assert 0 < len(data) <= cfg.budget.data_episodes * steps
    assert data.actions.dtype == np.float32
    low, high = (-1.0, 1.0) if task != "carracing" else (np.array([-1, 0, 0]), np.array([1, 1, 1]))
    assert np.all(data.actions >= low) and np.all(data.actions <= high)
    if task == "carracing":
        assert data.observations.dtype == np.uint8 and data.observations.shape[1:] == (3, 96, 96)


def test_other_seed_gives_other_data(tmp_path: Path) -> None:
    a, _ = get_dataset(compose_preset(None, tmp_path, "data_seed=0"))
    b, _ = get_dataset(compose_preset(None, tmp_path, "data_seed=1"))
    assert not np.array_equal(a.actions, b.actions)


def test_data_do_not_depend_on_parallelism(tmp_path: Path) -> None:
    one, _ = get_dataset(compose_preset(None, tmp_path / "one", "env.data_num_envs=1"))
    three, _ = get_dataset(compose_preset(None, tmp_path / "three", "env.data_num_envs=3",
                                          "budget.data_episodes=2"))
    for name in ("observations", "actions", "rewards", "obs_index"):
        assert np.array_equal(getattr(one, name), getattr(three, name)), name


def test_transitions_link_states_to_next_states(tmp_path: Path) -> None:
    data, _ = get_dataset(compose_preset(None, tmp_path))
    s, s_next = data.observations[data.obs_index], data.observations[data.obs_index + 1]
    # MountainCar: x' = x + v' exactly, before clipping at the left wall
    inside = s_next[:, 0] > -1.2 + 1e-6
    assert np.allclose(s_next[inside, 0], np.clip(s[inside, 0] + s_next[inside, 1], -1.2, 0.6), atol=1e-5)
    assert data.truncated[data.episode == 0][-1], "the data budget ends an episode by truncation"


@pytest.mark.parametrize(("task", "n_total", "n_train"), [("mountaincar", 12 * 999, 8400),
                                                            ("carracing", 57 * 1000, 54000)])
def test_paper_split_sizes(task: str, n_total: int, n_train: int) -> None:
    cfg = compose([f"env={task}", "budget=paper"])
    assert cfg.budget.data_episodes * cfg.budget.data_steps_per_episode == n_total
    assert round(n_total * cfg.env.data_train_fraction) == n_train


def _build_in_child(runs_dir: str, queue: mp.Queue) -> None:
    cfg = compose_preset(None, Path(runs_dir), "budget.data_episodes=4")
    _, artifact = get_dataset(cfg)
    queue.put((artifact.built, str(artifact.path)))


def test_two_processes_build_the_dataset_once(tmp_path: Path) -> None:
    results = in_two_processes(_build_in_child, str(tmp_path))
    assert sorted(built for built, _ in results) == [False, True]
    assert results[0][1] == results[1][1]
    assert not list((tmp_path / "artifacts" / "data").glob(".*tmp*")), "no temp dirs left behind"


def test_correlated_random_policy_keeps_uniform_marginals_and_correlates_in_time() -> None:
    import gymnasium as gym
    from scipy import stats

    from plls_bench.data.collect import action_stream

    box = gym.spaces.Box(np.array([-1.0, 0.0, 0.0]), np.array([1.0, 1.0, 1.0]), dtype=np.float32)
    uniform = action_stream(0, 20_000, box, "uniform")
    correlated = action_stream(0, 20_000, box, "correlated", correlation=0.95)
    for dim in range(3):
        width = box.high[dim] - box.low[dim]
        scaled = (correlated[:, dim] - box.low[dim]) / width
        # thin by 100 steps so the KS test sees nearly independent draws
        assert stats.kstest(scaled[::100], "uniform").pvalue > 0.01, dim
        lag1 = np.corrcoef(correlated[:-1, dim], correlated[1:, dim])[0, 1]
        assert lag1 > 0.9, dim
        assert abs(np.corrcoef(uniform[:-1, dim], uniform[1:, dim])[0, 1]) < 0.05, dim
    assert np.all(correlated >= box.low) and np.all(correlated <= box.high)


def test_data_policy_is_part_of_the_dataset_identity(tmp_path: Path) -> None:
    from plls_bench.data import dataset_key

    uniform = compose_preset(None, tmp_path, "env=carracing", "env.data_policy=uniform")
    correlated = compose_preset(None, tmp_path, "env=carracing")
    assert correlated.env.data_policy == "correlated"
    assert dataset_key(uniform) != dataset_key(correlated)
