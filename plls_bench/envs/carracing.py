"""CarRacing observations in the suite's pixel layout: channel-first uint8 ``(3, 96, 96)``."""
from __future__ import annotations

import gymnasium as gym
import numpy as np


class ChannelsFirst(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """HWC uint8 frames -> CHW uint8, a ``Box(0, 255)`` image space. Agents and stored data get the
    same frames; networks scale them to [0, 1] (SB3's image convention: the policy divides by 255)."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        super().__init__(env)
        h, w, c = env.observation_space.shape
        self.observation_space = gym.spaces.Box(0, 255, shape=(c, h, w), dtype=np.uint8)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(observation.transpose(2, 0, 1))
