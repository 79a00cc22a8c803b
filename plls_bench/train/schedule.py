"""A policy learner's budget in its own iterations, and when it evaluates: the one schedule the
trainers run (``train/ppo.py``, ``train/dbc.py``) and the dry run costs (``pipeline/plan.py``).

One iteration is the algorithm's ``steps_per_iteration`` agent steps (PPO: a rollout of
``n_envs x n_steps``; DBC: one agent step), each ``env.action_repeat`` env steps (frames). Budgets
are in env steps: ``budget.train_env_steps`` rounded up to whole iterations; an evaluation at
iteration 0, every ``budget.eval_every_env_steps`` rounded down to whole iterations (at least
one), and at the last iteration. Light on purpose (no torch): the plan imports it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from plls_bench.config import Config


@dataclass(frozen=True)
class Schedule:
    """The budget in iterations of the config's algorithm."""

    iterations: int               # iterations to run
    eval_every: int               # evaluate every this many iterations (and at 0 and the last)
    env_steps_per_iteration: int

    @classmethod
    def of(cls, cfg: Config) -> Schedule:
        algo = getattr(cfg.algo, cfg.algo.name, None)
        if algo is None:
            raise ValueError(f"algo={cfg.algo.name} learns no policy: it has no training schedule")
        per_iteration = algo.steps_per_iteration * cfg.env.action_repeat
        return cls(iterations=math.ceil(cfg.budget.train_env_steps / per_iteration),
                   eval_every=max(1, cfg.budget.eval_every_env_steps // per_iteration),
                   env_steps_per_iteration=per_iteration)

    def eval_at(self, iteration: int) -> bool:
        return iteration % self.eval_every == 0 or iteration == self.iterations

    def evaluations_through(self, iteration: int) -> int:
        """How many evaluations iterations 0 to ``iteration`` hold (a resumed run's count)."""
        last = iteration == self.iterations and iteration % self.eval_every != 0
        return iteration // self.eval_every + 1 + last

    @property
    def evaluations(self) -> int:
        """Evaluations of a whole run."""
        return self.evaluations_through(self.iterations)
