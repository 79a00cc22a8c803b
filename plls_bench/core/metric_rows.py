"""Typed rows of ``metrics/train.jsonl`` and ``metrics/eval.jsonl``: every trainer writes them and
the collector reads them, with no per-algorithm cases on either side.

On disk a row is one flat JSON object (sorted keys): the four counters of :class:`Counters`, then
a :class:`TrainRow`'s prefixed metrics (``loss/*``, ``train/*``, ``rollout/*``, ``perf/*``) or an
:class:`EvalRow`'s fields. That is the format runs have written since the suite began, so old run
dirs and the committed records read into the same rows (:meth:`TrainRow.from_record`,
:meth:`EvalRow.from_record`); a counter a hand-written or damaged row lacks reads as None.

What one ``iteration`` is differs per runner and is stated once, on its ``RunnerSpec``
(``iteration_unit``, ``plls_bench/pipeline/runner_registry.py``).
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from typing import Any, Protocol

import numpy as np

Lookup = Callable[[str, Any], Any]  # a dotted config lookup with a default (Trial.cfg, Experiment.cfg)


class At(Protocol):
    """Anything that says where a run stands (the training loop's ``Progress``)."""

    iteration: int
    agent_steps: int
    env_steps: int
    wall_s: float


@dataclass(frozen=True)
class Counters:
    """Where in training a row was written: ``iteration`` in the runner's unit, ``agent_steps``
    (steps of the learner's env, each env of a vector env counted), ``env_steps`` (frames: agent
    steps x action repeat), ``wall_s`` (seconds of training, summed over restarts)."""

    iteration: int | None
    agent_steps: int | None
    env_steps: int | None
    wall_s: float | None

    @staticmethod
    def of(at: At) -> dict[str, Any]:
        return {"iteration": at.iteration, "agent_steps": at.agent_steps, "env_steps": at.env_steps,
                "wall_s": at.wall_s}

    def x(self, axis: str) -> float | None:
        """This row's position on ``axis`` (a counter's name) as a float, None where it lacks one."""
        return number(getattr(self, axis, None))


_COUNTERS = tuple(f.name for f in fields(Counters))


@dataclass(frozen=True)
class TrainRow(Counters):
    """A ``train.jsonl`` row: the counters and the trainer's prefixed metrics."""

    metrics: dict[str, Any]

    @classmethod
    def at(cls, at: At, metrics: dict[str, Any]) -> TrainRow:
        return cls(**Counters.of(at), metrics=dict(metrics))

    def to_record(self) -> dict[str, Any]:
        return {**_present(self, _COUNTERS), **self.metrics}

    @classmethod
    def from_record(cls, record: dict[str, Any]) -> TrainRow:
        metrics = {k: v for k, v in record.items() if k not in _COUNTERS}
        return cls(**{k: record.get(k) for k in _COUNTERS}, metrics=metrics)


# which actions a test episode takes: the Gaussian's mean, or samples from it (docs/decisions.md#d20)
POLICIES = ("deterministic", "stochastic")


@dataclass(frozen=True)
class EvalRow(Counters):
    """An ``eval.jsonl`` row: the deterministic policy's test episodes (``episode_returns``,
    ``episode_lengths``, ``return_mean``) and, where the runner also samples actions on the same
    episodes (PPO), their ``*_stochastic`` counterparts; left out on disk when None."""

    episode_returns: list[float]
    episode_lengths: list[int]
    return_mean: float | None
    episode_returns_stochastic: list[float] | None = None
    episode_lengths_stochastic: list[int] | None = None
    return_mean_stochastic: float | None = None

    @classmethod
    def at(cls, at: At, **fields_: Any) -> EvalRow:
        return cls(**Counters.of(at), **fields_)

    def to_record(self) -> dict[str, Any]:
        return _present(self, tuple(asdict(self)))

    @classmethod
    def from_record(cls, record: dict[str, Any]) -> EvalRow | None:
        """The row, None when it has no usable return. A missing ``return_mean`` is the mean of
        ``episode_returns`` (rows written before it was), as is one that is not a finite number."""
        mean = _mean_of(record, "return_mean", "episode_returns")
        if mean is None:
            return None
        known = {f.name for f in fields(cls)}
        values = {k: record.get(k) for k in known if k != "return_mean"}
        values["episode_returns"] = list(record.get("episode_returns") or [])
        values["episode_lengths"] = list(record.get("episode_lengths") or [])
        return cls(**values, return_mean=mean)

    def mean_return(self, policy: str) -> float | None:
        """The mean test return of the ``policy`` in :data:`POLICIES`; None where it was not evaluated
        (a missing stochastic mean is that of its episodes, as for ``return_mean``)."""
        if policy not in POLICIES:
            raise ValueError(f"policy {policy!r}: expected one of {', '.join(POLICIES)}")
        if policy == "deterministic":
            return self.return_mean
        return _mean_of({"mean": self.return_mean_stochastic, "episodes": self.episode_returns_stochastic},
                        "mean", "episodes")


def parallel_envs(cfg: Lookup) -> int:
    """How many envs the learner steps at once: its algorithm's ``n_envs``, 1 where it has none."""
    return int(cfg(f"algo.{cfg('algo.name', None)}.n_envs", 1))


def number(value: object) -> float | None:
    """``value`` as a float when it is a finite number (not a bool), else None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return None
    return float(value)


def _mean_of(record: dict[str, Any], mean_key: str, episodes_key: str) -> float | None:
    value = number(record.get(mean_key))
    if value is not None:
        return value
    episodes = record.get(episodes_key)
    if isinstance(episodes, list) and episodes and all(number(v) is not None for v in episodes):
        return float(np.mean(episodes))
    return None


def _present(row: Any, names: tuple[str, ...]) -> dict[str, Any]:
    """The named fields of ``row`` that are not None (a counter or stochastic field it lacks)."""
    return {name: getattr(row, name) for name in names if getattr(row, name) is not None}
