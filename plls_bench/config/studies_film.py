"""Schemas of the MountainCar latent-space studies and of policy filmstrips (``study/``, ``filmstrip/``)."""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from omegaconf import MISSING

from plls_bench.config.checks import Validated, check, check_choice, check_positive
from plls_bench.core.hashing import stable_hash

# --------------------------------------------------------------------------- studies
STUDY_NAMES = ("multistep", "onestep", "generalisation")
LATENT_CHOICES = ("e", "mu")
# MountainCarContinuous-v0's bounds (gymnasium): the studies set its state and act in its box.
MOUNTAINCAR_POSITION, MOUNTAINCAR_SPEED, MOUNTAINCAR_ACTION = (-1.2, 0.6), 0.07, (-1.0, 1.0)


@dataclass
class StudyConfig(Validated):
    """A MountainCar latent-space study (Figs 7-9, Sec. 5.1): which actions, from which state.

    ``multistep`` applies the actions one after another from ``s0`` (a trajectory); ``onestep``
    and ``generalisation`` apply each action for one step from ``s0``. Actions are drawn
    uniformly, ``actions_per_range`` from each ``action_ranges`` entry in order; the end of a
    range nearer to zero is open, so ``[-1, 0]`` and ``[0, 1]`` give the paper's [-1, 0) and (0, 1].
    """

    name: str = MISSING
    s0: list[float] = MISSING
    action_ranges: list[list[float]] = MISSING
    actions_per_range: int = MISSING
    samples_per_action: int = 1
    decode: str = "e"
    knn: int = 10
    tracking_tolerance: float = 0.05

    def validate(self) -> None:
        check_choice(self.name, STUDY_NAMES, "study.name")
        check(len(self.s0) == 2, "study.s0", f"must be (x, x_dot), got {list(self.s0)}")
        low, high = MOUNTAINCAR_POSITION
        check(low <= self.s0[0] <= high, "study.s0", f"x = {self.s0[0]} is outside [{low}, {high}]")
        check(abs(self.s0[1]) <= MOUNTAINCAR_SPEED, "study.s0",
              f"x_dot = {self.s0[1]} is outside [-{MOUNTAINCAR_SPEED}, {MOUNTAINCAR_SPEED}]")
        check(len(self.action_ranges) > 0, "study.action_ranges", "needs at least one [low, high]")
        for i, bounds in enumerate(self.action_ranges):
            check(len(bounds) == 2 and MOUNTAINCAR_ACTION[0] <= bounds[0] < bounds[1] <= MOUNTAINCAR_ACTION[1],
                  f"study.action_ranges[{i}]", f"must be [low, high] with {MOUNTAINCAR_ACTION[0]} <= low < "
                  f"high <= {MOUNTAINCAR_ACTION[1]}, got {list(bounds)}")
        check_positive(self.actions_per_range, "study.actions_per_range")
        check_positive(self.samples_per_action, "study.samples_per_action")
        check_choice(self.decode, LATENT_CHOICES, "study.decode")
        check_positive(self.knn, "study.knn")
        check_positive(self.tracking_tolerance, "study.tracking_tolerance")
        if self.name == "generalisation":
            check(self.decode == "e", "study.decode", "generalisation decodes its samples e; mu is one point")
        else:  # docs/architecture.md's arrays hold one e per action for these studies
            check(self.samples_per_action == 1, "study.samples_per_action", f"{self.name} takes one e per action")
        check(self.knn < self.n_actions, "study.knn", f"must be < the {self.n_actions} actions")

    @property
    def n_actions(self) -> int:
        return len(self.action_ranges) * self.actions_per_range


@dataclass
class FilmstripConfig(Validated):
    """A filmstrip of a trained policy (Figs 11, 19, 22): one evaluation episode, a frame every
    ``interval`` env frames (steps counting action repeat), and its last frame.

    ``python -m plls_bench.film RUN_DIR`` composes ``conf/filmstrip/<env>.yaml``.
    ``presets`` declares which experiment presets ``reproduce`` films (their first trial, once
    done); it says nothing about how a strip is recorded, so it is not in :meth:`settings`.
    """

    interval: int = MISSING
    reset_options: dict[str, float] = field(default_factory=dict)
    goal: bool = False
    episode: int = 0
    frame_height: int = 200
    presets: list[str] = field(default_factory=list)

    def settings(self) -> dict[str, Any]:
        """What the recording depends on (written into filmstrip.json, hashed into its identity)."""
        return {k: v for k, v in asdict(self).items() if k != "presets"}

    def output_hash(self, run_config_hash: str | None, run_status: str | None, max_steps: int) -> str:
        """Identity of a strip: these settings and step cap, of a run in this config and state
        (a strip of an unfinished run's checkpoint is not the strip of the done run)."""
        return filmstrip_hash({"settings": self.settings(), "max_steps": max_steps or None,
                               "run_config_hash": run_config_hash, "run_status": run_status})

    def validate(self) -> None:
        check_positive(self.interval, "filmstrip.interval")
        check(isinstance(self.episode, int) and self.episode >= 0, "filmstrip.episode",
              f"must be a non-negative int, got {self.episode!r}")
        check_positive(self.frame_height, "filmstrip.frame_height")
        for i, name in enumerate(self.presets):
            check(bool(name) and "/" not in name, f"filmstrip.presets[{i}]", f"must be a preset name, got {name!r}")


def filmstrip_hash(meta: dict[str, Any]) -> str:
    """The identity hash of a strip from filmstrip.json's fields; also reads strips written before
    strips had a done marker of their own, whose filmstrip.json holds these same fields."""
    keys = ("settings", "max_steps", "run_config_hash", "run_status")
    return stable_hash({key: meta.get(key) for key in keys})
