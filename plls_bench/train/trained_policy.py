"""A trained policy as the layers above the learners see it, whatever learner made it.

Each learner turns its run's last checkpoint into a :class:`TrainedPolicy` (PPO:
``train.agent.trained_policy``; DBC: ``train.dbc.trained_policy``). The runner registry names
those loaders, and the filmstrip (``film/recording.py``) gets one handed in: the type lives
here, below all of them, and imports nothing that trains.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # types only: this module stays free of torch and the simulators
    from plls_bench.config import Config
    from plls_bench.repr.store import Representations

Act = Callable[[Any], Any]  # batched observations (1, *O) -> actions (1, *A), numpy arrays


@dataclass(frozen=True)
class TrainedPolicy:
    """A run's last checkpointed policy, ready to act deterministically (filmstrips)."""

    cfg: Config      # the run's recorded config, on the device the policy was loaded to
    act: Act
    checkpoint: str  # file name of the checkpoint it came from
    reprs: Representations  # its V_s / V_a, loaded (never trained) on that device


PolicyLoader = Callable[[Path, str], TrainedPolicy]  # (run dir, device) -> the run's policy
