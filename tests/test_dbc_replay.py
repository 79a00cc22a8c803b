"""The frame replay: stacks rebuilt from single frames equal the env's stacks, across episode
starts and ring-buffer wrap-around; chunks export and re-import exactly."""
from __future__ import annotations

from collections import deque
from pathlib import Path

import numpy as np
import pytest
import torch

from baselines.dbc import FrameReplay
from plls_bench.envs import make_env
from tests.conftest import compose_preset

K, SHAPE = 3, (3 * 3, 2, 2)  # frame stack 3 of (3, 2, 2) frames


class CountingEnv:
    """Frames are filled with a global counter; stacks built with a deque as DMCEnv does."""

    def __init__(self, episode_length: int) -> None:
        self.t, self.length, self.counter = 0, episode_length, 0
        self.frames: deque[np.ndarray] = deque(maxlen=K)

    def _frame(self) -> np.ndarray:
        self.counter += 1
        return np.full((3, 2, 2), self.counter % 256, dtype=np.uint8)

    def reset(self) -> np.ndarray:
        self.t, frame = 0, self._frame()
        for _ in range(K):
            self.frames.append(frame)
        return np.concatenate(list(self.frames))

    def step(self) -> tuple[np.ndarray, bool]:
        self.t += 1
        self.frames.append(self._frame())
        return np.concatenate(list(self.frames)), self.t == self.length


def fill(replay: FrameReplay, env: CountingEnv, steps: int, truth: dict[int, tuple]) -> None:
    """Run ``steps`` transitions, recording the true (obs, action, next_obs) by start slot."""
    obs = env.reset()
    replay.start_episode(obs)
    for i in range(steps):
        action = np.full(2, i, dtype=np.float32)
        next_obs, done = env.step()
        truth[replay.n_written - 1] = (obs, action, next_obs)
        replay.add(action, float(i), False, next_obs)
        obs = next_obs
        if done:
            obs = env.reset()
            replay.start_episode(obs)


def check_samples(replay: FrameReplay, truth: dict[int, tuple], n: int = 200) -> None:
    rng = np.random.default_rng(0)
    slots = replay.sample_indices(n, rng)
    assert len(slots) == n and (slots >= replay.oldest).all()
    for g, obs, next_obs in zip(slots, replay.stack(slots), replay.stack(slots + 1)):
        true_obs, action, true_next = truth[int(g)]
        assert np.array_equal(obs, true_obs) and np.array_equal(next_obs, true_next)
        assert np.array_equal(replay.actions[g % replay.slots], action)


def test_stacks_match_the_env_across_episodes() -> None:
    replay, truth = FrameReplay(SHAPE, K, 2, capacity=100, episode_length=7), {}
    fill(replay, CountingEnv(7), 30, truth)
    assert len(replay) == 30, "every transition, none across an episode boundary"
    check_samples(replay, truth)


def test_wrapped_ring_never_samples_overwritten_or_cross_episode_frames() -> None:
    replay, truth = FrameReplay(SHAPE, K, 2, capacity=20, episode_length=7), {}
    fill(replay, CountingEnv(7), 100, truth)
    assert replay.n_written > replay.slots
    assert 0 < len(replay) < 20
    check_samples(replay, truth, n=500)


def test_export_and_load_in_chunks_restore_the_buffer() -> None:
    replay, truth = FrameReplay(SHAPE, K, 2, capacity=20, episode_length=7), {}
    fill(replay, CountingEnv(7), 60, truth)
    cut = replay.oldest + 9
    chunks = [(replay.oldest, replay.export(replay.oldest, cut)), (cut, replay.export(cut, replay.n_written))]
    restored = FrameReplay(SHAPE, K, 2, capacity=20, episode_length=7)
    for start, arrays in chunks:
        restored.load(start, arrays)
    assert (restored.n_written, restored.oldest, len(restored)) == (replay.n_written, replay.oldest, len(replay))
    check_samples(restored, truth)
    with pytest.raises(ValueError, match="starts at slot"):
        restored.load(0, chunks[0][1])


def test_batch_tensors_and_memory_per_transition() -> None:
    replay = FrameReplay((9, 84, 84), 3, 6, capacity=1000, episode_length=250)
    obs = np.random.default_rng(0).integers(0, 255, (9, 84, 84), dtype=np.uint8)
    replay.start_episode(obs)
    replay.add(np.zeros(6), 1.5, True, obs)
    batch = replay.sample(4, np.random.default_rng(0), torch.device("cpu"))
    assert batch.obs.shape == (4, 9, 84, 84) and batch.obs.dtype == torch.uint8
    assert batch.reward.shape == (4, 1) and float(batch.reward[0]) == 1.5 and float(batch.not_done[0]) == 0.0
    # one (3, 84, 84) frame per slot instead of the reference's three (9, 84, 84) stacks
    assert replay.frames.shape == (replay.slots, 3, 84, 84)
    assert replay.reference_bytes_per_transition() / replay.bytes_per_slot() > 8.5


def test_stacks_match_the_real_cheetah_env(runs_dir: Path) -> None:
    cfg = compose_preset("cheetah_dbc", runs_dir).env
    env = make_env(cfg)
    replay, observations = FrameReplay(env.observation_space.shape, cfg.frame_stack, 6, 50, 250), []
    obs, _ = env.reset(seed=3)
    replay.start_episode(obs)
    observations.append(obs)
    for _ in range(5):
        obs, reward, terminated, _, _ = env.step(env.action_space.sample())
        replay.add(np.zeros(6), reward, terminated, obs)
        observations.append(obs)
    env.close()
    rebuilt = replay.stack(np.arange(6))
    assert all(np.array_equal(a, b) for a, b in zip(rebuilt, observations))
