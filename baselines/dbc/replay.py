"""A replay buffer that stores each frame once and rebuilds frame stacks when it samples.

The reference (deep_bisim4control utils.ReplayBuffer) keeps three full stacks per transition
(obs, next_obs and k_obs, each ``(3k, 84, 84)`` uint8): 190,548 bytes per cheetah transition.
Here slot ``t`` holds only the newest frame of o_t ``(3, 84, 84)`` plus a_t, r_t, the not-done
flag, the frame's position in its episode and whether it starts one: 21,205 bytes for a 6-D
action (9.0x less; 6.0x less than the reference without its unused ``k_obs``). An episode of T
transitions takes T + 1 slots (its reset frame). Stacks are rebuilt by indexing: frame
``t - min(j, step_in_episode[t])`` for j = k-1 .. 0, which repeats the first frame at an
episode's start exactly as the env's frame stack does.

Slots are addressed by a global counter ``n_written`` (never wraps) and stored at
``global % slots``; chunks of slots can be exported and re-imported, so a checkpoint writes only
what is new since the last one.
"""
from __future__ import annotations

import math

import numpy as np
import torch

from baselines.dbc.agent import Batch

_FIELDS = ("frames", "actions", "rewards", "not_done", "first", "episode_step")


class FrameReplay:
    """Ring buffer of frames for observations ``(frame_stack * C, *rest)`` (pixels, stacked along
    channels) or ``(D,)`` vectors with ``frame_stack=1``."""

    def __init__(self, obs_shape: tuple[int, ...], frame_stack: int, action_dim: int,
                 capacity: int, episode_length: int) -> None:
        if obs_shape[0] % frame_stack:
            raise ValueError(f"observation shape {obs_shape} is not {frame_stack} stacked frames")
        self.frame_stack = frame_stack
        self.frame_shape = (obs_shape[0] // frame_stack, *obs_shape[1:])
        dtype = np.uint8 if len(obs_shape) == 3 else np.float32
        # room for `capacity` transitions and the reset frame of each episode among them
        self.slots = capacity + math.ceil(capacity / episode_length) + 1
        self.frames = np.zeros((self.slots, *self.frame_shape), dtype=dtype)
        self.actions = np.zeros((self.slots, action_dim), dtype=np.float32)
        self.rewards = np.zeros(self.slots, dtype=np.float32)
        self.not_done = np.ones(self.slots, dtype=np.float32)
        self.first = np.zeros(self.slots, dtype=bool)
        self.episode_step = np.zeros(self.slots, dtype=np.int64)
        self.n_written = 0  # global index of the next slot
        self.floor = 0      # no slot below this global index is held (raised by a resumed load)

    # ------------------------------------------------------------------ sizes
    @property
    def nbytes(self) -> int:
        return sum(getattr(self, name).nbytes for name in _FIELDS)

    def bytes_per_slot(self) -> int:
        return self.nbytes // self.slots

    def reference_bytes_per_transition(self) -> int:
        """The reference layout: obs, next_obs and k_obs stacks, action, two rewards, not-done."""
        obs_bytes = self.frame_stack * self.frames[0].nbytes
        return 3 * obs_bytes + self.actions[0].nbytes + 3 * 4

    def __len__(self) -> int:
        """Transitions that can be sampled."""
        return int(self._valid(np.arange(self.oldest, self.n_written)).sum())

    # ------------------------------------------------------------------ writing
    def _write_frame(self, obs: np.ndarray, first: bool) -> None:
        slot = self.n_written % self.slots
        self.frames[slot] = obs[-self.frame_shape[0]:]  # the newest frame of the stack
        self.first[slot] = first
        self.episode_step[slot] = 0 if first else self.episode_step[(self.n_written - 1) % self.slots] + 1
        self.not_done[slot] = 1.0
        self.n_written += 1

    def start_episode(self, obs: np.ndarray) -> None:
        """Store an episode's first observation ``(*O,)``."""
        self._write_frame(obs, first=True)

    def add(self, action: np.ndarray, reward: float, terminated: bool, next_obs: np.ndarray) -> None:
        """Record (a_t, r_t, terminated) for the newest observation and store o_{t+1}."""
        if self.n_written == 0:
            raise RuntimeError("FrameReplay.add before start_episode")
        slot = (self.n_written - 1) % self.slots
        self.actions[slot] = action
        self.rewards[slot] = reward
        self.not_done[slot] = 0.0 if terminated else 1.0  # time-limit ends bootstrap (reference)
        self._write_frame(next_obs, first=False)

    # ------------------------------------------------------------------ reading
    @property
    def oldest(self) -> int:
        """Global index of the oldest slot still held."""
        return max(self.floor, self.n_written - self.slots)

    def _valid(self, g: np.ndarray) -> np.ndarray:
        """Whether global slots ``g`` start a sampleable transition: o_{t+1} is stored in the same
        episode and o_t's whole frame stack is still in the buffer."""
        nxt = (g + 1) % self.slots
        history = np.minimum(self.frame_stack - 1, self.episode_step[g % self.slots])
        return (g + 1 < self.n_written) & ~self.first[nxt] & (g - history >= self.oldest)

    def stack(self, g: np.ndarray) -> np.ndarray:
        """Observations ``(len(g), *O)`` whose newest frames are global slots ``g``."""
        back = np.arange(self.frame_stack - 1, -1, -1)                                # k-1 .. 0
        offsets = np.minimum(back[None, :], self.episode_step[g % self.slots][:, None])
        frames = self.frames[(g[:, None] - offsets) % self.slots]                     # (B, k, *F)
        return frames.reshape(len(g), -1, *self.frame_shape[1:])

    def sample_indices(self, batch_size: int, rng: np.random.Generator) -> np.ndarray:
        """``batch_size`` valid global slots, uniformly among the sampleable transitions."""
        chosen = np.empty(0, dtype=np.int64)
        while len(chosen) < batch_size:  # rejection: invalid slots are ~1 per episode
            g = rng.integers(self.oldest, max(self.n_written, self.oldest + 1), size=2 * batch_size)
            valid = g[self._valid(g)]
            if len(valid) == 0 and len(self) == 0:
                raise RuntimeError("FrameReplay.sample on a buffer without complete transitions")
            chosen = np.concatenate([chosen, valid])
        return chosen[:batch_size]

    def sample(self, batch_size: int, rng: np.random.Generator, device: torch.device) -> Batch:
        g = self.sample_indices(batch_size, rng)
        slot = g % self.slots

        def tensor(x: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(x, device=device)

        return Batch(obs=tensor(self.stack(g)), action=tensor(self.actions[slot]),
                     reward=tensor(self.rewards[slot, None]), next_obs=tensor(self.stack(g + 1)),
                     not_done=tensor(self.not_done[slot, None]))

    # ------------------------------------------------------------------ persistence
    def export(self, start: int, end: int) -> dict[str, np.ndarray]:
        """Arrays of global slots ``[start, end)``; ``start`` must still be in the buffer."""
        if start < self.oldest or end > self.n_written or start > end:
            raise ValueError(f"slots [{start}, {end}) are not in the buffer "
                             f"[{self.oldest}, {self.n_written})")
        index = np.arange(start, end) % self.slots
        return {name: getattr(self, name)[index] for name in _FIELDS}

    def load(self, start: int, arrays: dict[str, np.ndarray]) -> None:
        """Write exported slots back at global ``start``: ``n_written`` (chunks in order), or any
        slot of an empty buffer (older chunks were dropped as overwritten)."""
        if self.n_written == 0:
            self.floor = self.n_written = start
        if start != self.n_written:
            raise ValueError(f"replay chunk starts at slot {start}, buffer holds {self.n_written}")
        n = len(arrays["frames"])
        index = np.arange(start, start + n) % self.slots
        for name in _FIELDS:
            getattr(self, name)[index] = arrays[name]
        self.n_written += n
