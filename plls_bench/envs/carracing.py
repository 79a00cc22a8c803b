"""CarRacing observations in the suite's pixel layout: channel-first, float32 in [0, 1]."""
from __future__ import annotations

import gymnasium as gym
import numpy as np


class ChannelsFirst(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """HWC uint8 frames -> CHW, as uint8 (for stored data) or float32 in [0, 1] (for agents)."""

    def __init__(self, env: gym.Env, as_float: bool = True) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, as_float=as_float)
        super().__init__(env)
        h, w, c = env.observation_space.shape
        self.as_float = as_float
        if as_float:
            self.observation_space = gym.spaces.Box(0.0, 1.0, shape=(c, h, w), dtype=np.float32)
        else:
            self.observation_space = gym.spaces.Box(0, 255, shape=(c, h, w), dtype=np.uint8)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        chw = np.ascontiguousarray(observation.transpose(2, 0, 1))
        return chw.astype(np.float32) / 255.0 if self.as_float else chw
