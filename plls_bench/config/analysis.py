"""Schemas of the MountainCar latent-space studies and of policy filmstrips (``study/``, ``filmstrip/``)."""
from __future__ import annotations

from dataclasses import dataclass, field

from omegaconf import MISSING

from plls_bench.config.checks import Validated, check, check_choice, check_positive


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
        else:  # the README's arrays hold one e per action for these studies
            check(self.samples_per_action == 1, "study.samples_per_action", f"{self.name} takes one e per action")
        check(self.knn < self.n_actions, "study.knn", f"must be < the {self.n_actions} actions")

    @property
    def n_actions(self) -> int:
        return len(self.action_ranges) * self.actions_per_range


@dataclass
class FilmstripConfig(Validated):
    """A filmstrip of a trained policy (Figs 11, 19, 22): one evaluation episode, a frame every
    ``interval`` env frames (steps counting action repeat), and its last frame.

    ``python -m plls_bench.analysis.filmstrip RUN_DIR`` composes ``conf/filmstrip/<env>.yaml``.
    """

    interval: int = MISSING
    reset_options: dict[str, float] = field(default_factory=dict)
    goal: bool = False
    episode: int = 0
    frame_height: int = 200

    def validate(self) -> None:
        check_positive(self.interval, "filmstrip.interval")
        check(isinstance(self.episode, int) and self.episode >= 0, "filmstrip.episode",
              f"must be a non-negative int, got {self.episode!r}")
        check_positive(self.frame_height, "filmstrip.frame_height")
