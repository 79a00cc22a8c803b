"""MountainCar driven from a chosen state: what the studies (Figs 7-9) do to the car.

The studies start the car at a state the paper names, which a reset cannot reach, so they set
the unwrapped env's ``state`` (gymnasium's ``Continuous_MountainCarEnv`` keeps ``(x, x_dot)``
there) and step the unwrapped env: its physics, without the time limit (the multi-step study is
1000 steps, the limit 999) and without ending at the goal (the car simply keeps being driven).
"""
from __future__ import annotations

import gymnasium as gym
import numpy as np

from plls_bench.config import EnvConfig
from plls_bench.envs import make_env


class MountainCar:
    """One MountainCarContinuous env whose state is set directly."""

    def __init__(self, cfg: EnvConfig) -> None:
        if cfg.name != "mountaincar":
            raise ValueError(f"MountainCar needs env mountaincar, got {cfg.name!r}")
        self._env = make_env(cfg)
        self._env.reset(seed=0)  # initialises the env; every rollout then sets its own state
        self._car = self._env.unwrapped
        space = self._env.observation_space
        assert isinstance(space, gym.spaces.Box)
        self.state_range = (space.high - space.low).astype(np.float64)  # (2,): x and x_dot spans
        box = self._env.action_space
        assert isinstance(box, gym.spaces.Box)
        self.action_low, self.action_high = float(box.low[0]), float(box.high[0])

    def close(self) -> None:
        self._env.close()

    def __enter__(self) -> MountainCar:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _step(self, action: float) -> np.ndarray:
        state, *_ = self._car.step(np.array([action], dtype=np.float32))
        return np.asarray(state, dtype=np.float64)

    def trajectory(self, s0: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """States ``(N + 1, 2)`` visited applying ``actions`` ``(N,)`` in turn from ``s0`` ``(2,)``."""
        self._car.state = np.array(s0, dtype=np.float64)
        return np.stack([np.asarray(s0, dtype=np.float64), *(self._step(a) for a in actions)])

    def one_step(self, s0: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Next states ``(*actions.shape, 2)``: each action applied once from ``s0`` ``(2,)``."""
        flat = []
        for action in np.ravel(actions):
            self._car.state = np.array(s0, dtype=np.float64)
            flat.append(self._step(action))
        return np.reshape(np.stack(flat), (*np.shape(actions), 2))
