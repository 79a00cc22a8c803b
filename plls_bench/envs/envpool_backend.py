"""envpool's C++ engine behind the suite's two env interfaces (``env.backend: envpool``).

:class:`EnvpoolVecEnv` is a stable-baselines3 ``VecEnv`` with SB3's semantics exactly: an env
that finishes is reset *on the same step*, its last observation is returned in
``infos[i]["terminal_observation"]`` and a time limit sets ``infos[i]["TimeLimit.truncated"]``.
envpool instead resets an env on the step *after* it finished (that step ignores the action and
returns reward 0); the adapter resets the finished envs explicitly right away, so envpool's own
delayed reset never happens. :class:`EnvpoolDataEnvs` is the small part of gymnasium's
``VectorEnv`` API that random-policy collection uses.

Seeding. envpool seeds its envs when the pool is built (env i with ``seed + i``, or the list
``env_seed``), and an env's later episodes continue its own random stream, as a gymnasium env's
``np_random`` does after its first seeded reset. So ``seed(s)`` here only records ``s``, and the
next ``reset()`` builds a new pool with it (about 2 ms). Evaluation seeds every wave before it
resets, so test episode j always runs on the track of seed ``eval_seed + j`` -- of *this*
backend: the two engines draw different tracks from the same seed, which is why the backend is
part of every config hash, artifact key and run-dir variant.

Observations are converted to the suite's layout: channel-first uint8 pixels, for agents and stored
data alike (as :class:`plls_bench.envs.carracing.ChannelsFirst` does for gymnasium).
"""
from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvObs, VecEnvStepReturn

# gymnasium id -> envpool task id, for the tasks envpool ships
ENVPOOL_TASKS: dict[str, str] = {
    "CarRacing-v3": "CarRacing-v3",
    "MountainCarContinuous-v0": "MountainCarContinuous-v0",
}


@contextlib.contextmanager
def _quiet_spaces() -> Iterator[None]:
    """envpool builds its Box spaces from float64 bounds, at every pool and space access; gymnasium
    warns each time. Silenced here only, for that message."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*precision lowered by casting to float32", category=UserWarning)
        yield


def _make_pool(task_id: str, n_envs: int, seeds: Sequence[int], max_episode_steps: int,
               num_threads: int) -> Any:
    import envpool  # lazy: the C++ engine is only loaded when a config asks for it

    with _quiet_spaces():
        return envpool.make(task_id, env_type="gymnasium", num_envs=n_envs, batch_size=n_envs,
                            num_threads=num_threads, env_seed=[int(s) % 2**31 for s in seeds],
                            max_episode_steps=max_episode_steps)


def _spaces(task_id: str, max_episode_steps: int) -> tuple[gym.spaces.Box, gym.spaces.Box]:
    """One env's observation and action spaces (from a one-env pool)."""
    probe = _make_pool(task_id, 1, [0], max_episode_steps, 1)
    try:
        with _quiet_spaces():
            return probe.observation_space, probe.action_space
    finally:
        probe.close()


class _Layout:
    """envpool observations -> the suite's layout (pixels HWC uint8 -> CHW uint8)."""

    def __init__(self, space: gym.spaces.Box) -> None:
        self.pixels = len(space.shape) == 3
        if self.pixels:
            h, w, c = space.shape
            self.space = gym.spaces.Box(0, 255, (c, h, w), np.uint8)
        else:
            self.space = gym.spaces.Box(space.low.astype(np.float32), space.high.astype(np.float32), space.shape,
                                        np.float32)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """``(n, *envpool shape)`` -> ``(n, *self.space.shape)``."""
        if not self.pixels:
            return np.asarray(obs, dtype=np.float32)
        return np.ascontiguousarray(np.asarray(obs, dtype=np.uint8).transpose(0, 3, 1, 2))


def _by_env_id(info: dict[str, Any], *arrays: np.ndarray) -> list[np.ndarray]:
    """Rows of ``arrays`` sorted by ``info["env_id"]`` (envpool may return envs in any order)."""
    order = np.argsort(info["env_id"])
    return [np.asarray(a)[order] for a in arrays]


class EnvpoolVecEnv(VecEnv):
    """``n_envs`` envpool envs as an SB3 ``VecEnv`` (see the module docstring)."""

    def __init__(self, task_id: str, n_envs: int, max_episode_steps: int, num_threads: int = 0,
                 seed: int = 0) -> None:
        self.task_id, self.max_episode_steps, self.num_threads = task_id, max_episode_steps, num_threads
        self._seed, self._pool, self._actions = seed, None, None
        observation_space, action_space = _spaces(task_id, max_episode_steps)  # envpool's spaces are per env
        self._layout = _Layout(observation_space)
        self._low, self._high = action_space.low, action_space.high
        super().__init__(n_envs, self._layout.space, gym.spaces.Box(
            self._low.astype(np.float32), self._high.astype(np.float32), action_space.shape, np.float32))

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Env i of the next ``reset()`` is seeded ``seed + i`` (a new pool is built then)."""
        if seed is not None:
            self._seed = int(seed)
        return [self._seed + i for i in range(self.num_envs)]

    def reset(self) -> VecEnvObs:
        if self._pool is not None:
            self._pool.close()
        seeds = [self._seed + i for i in range(self.num_envs)]
        self._pool = _make_pool(self.task_id, self.num_envs, seeds, self.max_episode_steps, self.num_threads)
        obs, info = self._pool.reset()
        (obs,) = _by_env_id(info, obs)
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return self._layout(obs)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.clip(np.asarray(actions, dtype=np.float32).reshape(self.num_envs, -1),
                                self._low, self._high)

    def step_wait(self) -> VecEnvStepReturn:
        if self._pool is None:
            raise RuntimeError("EnvpoolVecEnv.step() before reset()")
        obs, rewards, terminated, truncated, info = self._pool.step(self._actions, np.arange(self.num_envs))
        obs, rewards, terminated, truncated = _by_env_id(info, obs, rewards, terminated, truncated)
        obs = self._layout(obs)
        dones = terminated | truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        finished = np.flatnonzero(dones)
        for i in finished:
            infos[i]["terminal_observation"] = obs[i].copy()
            infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        if len(finished):
            first_obs, reset_info = self._pool.reset(finished.astype(np.int32))
            order = np.argsort(reset_info["env_id"])
            obs[finished] = self._layout(np.asarray(first_obs)[order])
        return obs, np.asarray(rewards, dtype=np.float32), dones, infos

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool = None

    # No gymnasium envs live behind this VecEnv: attribute access answers like unwrapped envs.
    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        if attr_name == "render_mode":
            return [None] * len(self._get_indices(indices))
        raise AttributeError(f"EnvpoolVecEnv has no per-env attribute {attr_name!r}")

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        raise AttributeError(f"EnvpoolVecEnv cannot set per-env attribute {attr_name!r}")

    def env_method(self, method_name: str, *args: Any, indices: Any = None, **kwargs: Any) -> list[Any]:
        raise AttributeError(f"EnvpoolVecEnv has no per-env method {method_name!r}")

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False] * len(self._get_indices(indices))


class EnvpoolDataEnvs:
    """What random-policy collection needs of a gymnasium ``VectorEnv``: ``reset(seed=[...])``
    seeds env i with ``seed[i]`` (a new pool), ``step`` returns the 5-tuple in env order.
    Finished envs are reset by envpool on their next step; the collector drops those steps."""

    def __init__(self, task_id: str, n_envs: int, max_episode_steps: int, num_threads: int = 0) -> None:
        self.task_id, self.num_envs, self.max_episode_steps = task_id, n_envs, max_episode_steps
        self.num_threads, self._pool = num_threads, None
        observation_space, self.single_action_space = _spaces(task_id, max_episode_steps)
        self._layout = _Layout(observation_space)

    def reset(self, seed: Sequence[int]) -> tuple[np.ndarray, dict[str, Any]]:
        self.close()
        self._pool = _make_pool(self.task_id, self.num_envs, seed, self.max_episode_steps, self.num_threads)
        obs, info = self._pool.reset()
        (obs,) = _by_env_id(info, obs)
        return self._layout(obs), {}

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        actions = np.clip(np.asarray(actions, dtype=np.float32), self.single_action_space.low,
                          self.single_action_space.high)
        obs, rewards, terminated, truncated, info = self._pool.step(actions, np.arange(self.num_envs))
        obs, rewards, terminated, truncated = _by_env_id(info, obs, rewards, terminated, truncated)
        return self._layout(obs), rewards, terminated, truncated, {}

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool = None
