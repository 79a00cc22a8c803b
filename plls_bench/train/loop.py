"""The training skeleton every trainer runs in (PPO: :mod:`plls_bench.train.ppo`, DBC:
:mod:`plls_bench.train.dbc`)::

    setup -> restore -> drop metric rows newer than the checkpoint -> start
    [fresh: evaluate at 0 when due, checkpoint when due]
    while iteration < iterations:
        train_iteration -> train row -> evaluate when due -> eval row -> report -> checkpoint when due
        [after a checkpoint: stop if the next one would come after ``time_limit_min``]
    (before the first interval too, where the trainer foretells a long one)

A trainer builds its env, agent, buffer and logger once in ``setup`` and supplies the steps; this
module owns their order, resume, the wall clock, the metric rows (:mod:`plls_bench.core.metric_rows`) and
the progress bar. A checkpoint at iteration k covers every metric row with ``iteration <= k``: a
restarted run drops the newer rows and redoes those iterations, so the history ends complete and
without duplicates.

``time_limit_min`` (0: none) ends a run early, at a checkpoint, for cluster jobs with a wall-clock
limit and compute spread over sessions: before the first interval and after each checkpoint the
loop stops if this process's time so far plus the next interval's estimate (:class:`TimeLimit`:
its longest recent checkpoint interval, or the trainer's ``interval_ahead_s`` where it knows the
next one is longer, as DBC's burst of ``init_steps`` updates) would pass the limit, and raises
:class:`TimeLimitReached`; the runner leaves the run ``stopped`` and the next launch resumes it.
Nothing past the checkpoint is lost, unlike a job killed at its limit.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, Protocol

from tqdm import tqdm  # the type of the bar progress_bar returns

from plls_bench.config import Config
from plls_bench.core.metric_rows import EvalRow, TrainRow
from plls_bench.core.progress_bars import progress_bar
from plls_bench.core.signals import signals_deferred
from plls_bench.rundirs.run_dir import Run


@dataclass(frozen=True)
class Progress:
    """Where a run stands. ``iteration`` counts the runner's unit (its trainer's docstring; docs/architecture.md,
    "What each runner writes"): PPO one rollout of ``n_envs x n_steps`` and its update, DBC one
    agent step. ``agent_steps`` counts steps of the learner's env (each env of a vector env),
    ``env_steps`` frames (agent steps x action repeat); ``wall_s`` sums over restarts;
    ``evaluations`` is the number done so far; ``episodes`` the training episodes finished, where
    the runner keeps count (DBC; PPO reports them per iteration in ``rollout/episodes``)."""

    iteration: int = 0
    agent_steps: int = 0
    wall_s: float = 0.0  # third, so a checkpoint's Progress(iteration, agent_steps, wall_s) reads
    env_steps: int = 0
    evaluations: int = 0
    episodes: int = 0


class TimeLimitReached(Exception):
    """A run stopped at a checkpoint because the next would come after ``time_limit_min``."""

    def __init__(self, at: Progress, limit_min: float) -> None:
        super().__init__(f"stopped at iteration {at.iteration} ({at.env_steps:,} env steps): the next checkpoint "
                         f"would come after time_limit_min={limit_min:g}; run the same command again to resume")
        self.at = at


class TimeLimit:
    """Whether to stop after a checkpoint: this process's training time plus the longer of the last
    checkpoint interval that held an evaluation and the last that did not would pass ``limit_min``
    minutes (0: never). Both kinds, whatever the evaluation cadence: DBC's intervals that hold an
    evaluation (one in ten episodes on cheetah) are longer than those that only end an episode. The
    last of each kind only: a fresh DBC run's burst of ``init_steps`` updates makes one interval of
    about 20 CPU-minutes that never comes back. No interval before it foretells it, so the trainer
    passes its own estimate of such an interval as ``ahead_s``, and an interval it foretold is not
    kept once over: those after it are like those before it (kept, it stopped a sitting with time
    left for hundreds of steps). Times are ``now()`` seconds."""

    def __init__(self, limit_min: float, now: Callable[[], float] = time.perf_counter) -> None:
        self.limit_s, self.now = 60.0 * limit_min, now
        self.started = self.last_checkpoint = now()
        self.last_interval: dict[bool, float] = {}  # evaluated or not -> seconds
        self.foretold = False  # the interval under way is one the trainer foretold

    def mark(self, ahead_s: float = 0.0) -> None:
        """Start timing the next checkpoint interval here (set-up and restore time are not one);
        ``ahead_s``: the trainer's estimate of it, when it foretells one (0: none)."""
        self.last_checkpoint, self.foretold = self.now(), ahead_s > 0

    @property
    def active(self) -> bool:
        return self.limit_s > 0

    def stop_after_checkpoint(self, evaluated: bool, ahead_s: float = 0.0) -> bool:
        """Call right after each checkpoint of the training loop; ``evaluated``: the interval held
        an evaluation; ``ahead_s``: the trainer's estimate of the next interval (0: none)."""
        now = self.now()
        if not self.foretold:
            self.last_interval[evaluated] = now - self.last_checkpoint
        self.last_checkpoint, self.foretold = now, ahead_s > 0
        return self.would_pass(max([*self.last_interval.values(), ahead_s]))

    def would_pass(self, next_s: float) -> bool:
        """Whether an interval of ``next_s`` seconds from now would end past the limit."""
        return self.active and (self.now() - self.started) + next_s > self.limit_s


class Trainer(Protocol):
    """What a runner supplies to :func:`train`."""

    unit: str        # the progress bar's name for one iteration
    iterations: int  # iterations in the whole run

    def setup(self) -> None:
        """Build envs, agent, buffer and logger (once)."""

    def restore(self) -> Progress | None:
        """Load the last checkpoint (agent, buffer, RNG states); None for a fresh run."""

    def start(self, at: Progress, resumed: bool) -> None:
        """Ready to train from ``at``: accounting files, logger, env resets."""

    def train_iteration(self, at: Progress) -> tuple[Progress, dict[str, Any] | None]:
        """One iteration; the new position and the metrics of a train row, if one is due."""

    def eval_due(self, at: Progress) -> bool: ...

    def evaluate(self, at: Progress) -> EvalRow: ...

    def report(self, at: Progress, row: TrainRow | None, evaluation: EvalRow | None) -> None:
        """Hand the iteration's rows to the trainer's own loggers (before its checkpoint)."""

    def checkpoint_due(self, at: Progress, evaluated: bool) -> bool: ...

    def interval_ahead_s(self, at: Progress) -> float:
        """Seconds the checkpoint interval from ``at`` will take, where the trainer knows it is
        longer than the last ones (DBC's burst of updates); 0 otherwise. Asked under a time limit only."""

    def checkpoint(self, at: Progress) -> None: ...

    def close(self) -> None: ...


class _Clock:
    """Wall seconds of training so far: those of earlier starts plus this one's."""

    def __init__(self, before: float) -> None:
        self.before, self.started = before, time.perf_counter()

    def __call__(self) -> float:
        return round(self.before + time.perf_counter() - self.started, 3)


def train(trainer: Trainer, run: Run, cfg: Config) -> None:
    """Run ``trainer`` to its last iteration in ``run``, resuming from its checkpoint if any; raises
    :class:`TimeLimitReached` after a checkpoint when ``cfg.time_limit_min`` would pass."""
    limit = TimeLimit(cfg.time_limit_min)
    trainer.setup()
    try:
        restored = trainer.restore()
        at = restored or Progress()
        for stream in ("train", "eval"):
            run.truncate_metrics(stream, lambda r: restored is not None and r.get("iteration", -1) <= at.iteration)
        trainer.start(at, resumed=restored is not None)
        clock = _Clock(at.wall_s)
        with progress_bar(total=trainer.iterations, initial=at.iteration, unit=trainer.unit, disable=not cfg.progress,
                          desc=f"{cfg.runner} {cfg.experiment} seed={cfg.seed}") as bar:
            if restored is None:  # a resumed run's checkpoint came after its point's evaluation
                at, _ = _point(trainer, run, replace(at, wall_s=clock()), None, clock, bar)
            # only a foretold interval stops a run before its first: each launch makes progress otherwise
            ahead = trainer.interval_ahead_s(at) if limit.active and at.iteration < trainer.iterations else 0.0
            limit.mark(ahead)
            if ahead > 0 and limit.would_pass(ahead):
                raise TimeLimitReached(at, cfg.time_limit_min)
            evaluations_then = at.evaluations  # at the last checkpoint
            while at.iteration < trainer.iterations:
                at, metrics = trainer.train_iteration(at)
                at = replace(at, wall_s=clock())
                row = None if metrics is None else TrainRow.at(at, metrics)
                if row is not None:
                    run.log("train", row.to_record())
                at, checkpointed = _point(trainer, run, at, row, clock, bar)
                bar.update(1)
                if not checkpointed:
                    continue
                evaluated = at.evaluations > evaluations_then
                ahead = trainer.interval_ahead_s(at) if limit.active else 0.0
                if at.iteration < trainer.iterations and limit.stop_after_checkpoint(evaluated, ahead):
                    raise TimeLimitReached(at, cfg.time_limit_min)
                evaluations_then = at.evaluations
    finally:
        trainer.close()


def _point(trainer: Trainer, run: Run, at: Progress, row: TrainRow | None, clock: _Clock,
           bar: tqdm) -> tuple[Progress, bool]:
    """Evaluate when due, report, checkpoint when due; the position with the evaluation counted,
    and whether a checkpoint was written."""
    evaluation = trainer.evaluate(at) if trainer.eval_due(at) else None
    if evaluation is not None:
        run.log("eval", evaluation.to_record())
        at = replace(at, evaluations=at.evaluations + 1)
        bar.set_postfix({k: round(v, 2) for k, v in (("return_mean", evaluation.return_mean),
                         ("return_mean_stochastic", evaluation.return_mean_stochastic)) if v is not None},
                        refresh=False)
    trainer.report(at, row, evaluation)
    due = trainer.checkpoint_due(at, evaluation is not None)
    if due:
        with signals_deferred():  # a stop or requeue signal waits for the checkpoint to be written
            trainer.checkpoint(replace(at, wall_s=clock()))
    return at, due
