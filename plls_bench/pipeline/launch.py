"""Launching a plan's pending trials as Hydra multiruns: on this machine one per trial, from a queue
that keeps ``jobs`` trials running (``--launcher local``: 1, ``joblib``: ``--jobs``); on SLURM one
per preset, whose jobs submitit runs side by side.

One multirun per preset would leave cores idle on this machine whenever a preset's pending trials
do not divide by the job count (3 trials on 2 cores: the third runs alone), and so would a sweep
whose variants each have one trial left. The queue starts the next pending trial of any preset of
the same stage as soon as a trial ends, the shortest first, or the longest (:func:`queue_order`). Stages are the
runners' plan order (:attr:`plls_bench.pipeline.runner_registry.RunnerSpec.order`): artifacts are built before
the presets that read them, and the learners (PPO, DBC) share the last stage. A queue may have a
deadline (``reproduce --stop-after-min``): each trial gets the time left as its ``time_limit_min``
when it starts, and none starts that could not reach a checkpoint, or its end, by then
(:func:`start_minutes`).
"""
from __future__ import annotations

import heapq
import itertools
import os
import signal
import subprocess
import sys
import time
from collections import deque
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass

from plls_bench.core.signals import Terminated
from plls_bench.pipeline.plan import PresetPlan, Trial
from plls_bench.pipeline.runner_registry import runner_spec
from plls_bench.rundirs.run_dir import STATUS_STOPPED, Run

Launch = Callable[[], list[str] | None]  # a queued trial's argv when it starts; None: skip it
POLL_SECONDS = 0.5
# On Ctrl-C the trials get SIGINT from the terminal too; a trial still running after this long
# (reproduce alone was signalled) gets SIGTERM, which stops it at a resumable point (status stopped).
INTERRUPT_GRACE_SECONDS = 30.0
# No trial starts with less time than this left to the deadline: a trial runs at least to its
# first checkpoint whatever its limit, so it would overrun the deadline for little work. A trial
# with an estimate needs the estimated time to its first stop too (start_minutes).
MIN_START_MINUTES = 2.0
# Which pending trial the queue starts next (reproduce --queue-order): the least estimated time left
# (trials end, and are recorded, soonest), or the most (the classic longest-first rule: the whole
# queue ends soonest, for when only all trials of an arm together make a verdict).
QUEUE_ORDERS = ("shortest", "longest")


def start_minutes(plan: PresetPlan, trial: Trial, launcher: str = "joblib") -> float:
    """The least time left to the deadline that ``trial`` may start with under ``launcher``:
    MIN_START_MINUTES, or longer if it is estimated to stop first further off
    (``PresetPlan.first_stop_seconds``, CPU seconds over its :func:`trial_threads`): a learner at
    its first checkpoint (one CNN PPO iteration on 2 cores is about 10 minutes; started with 4
    left, it overran the deadline by 6), any other runner at its end."""
    cpu_seconds = plan.first_stop_seconds.get(trial.seed, 0.0)
    return max(MIN_START_MINUTES, cpu_seconds / trial_threads(plan, trial, launcher) / 60.0)


def launcher_overrides(launcher: str, extra: list[str]) -> list[str]:
    """Hydra overrides that select a launcher (conf/hydra/launcher/) for every multirun."""
    if launcher == "joblib":
        # --jobs one-trial multiruns at once (the basic launcher, each its own process), with one
        # torch thread each so they do not oversubscribe the cores
        return ["torch_threads=1", *extra]
    if launcher == "slurm":
        return ["hydra/launcher=slurm", *extra]
    return list(extra)


def multirun_command(plan: PresetPlan, profile: str, runs_dir: str, overrides: list[str],
                     seeds: Sequence[int] | None = None, time_limit_min: float = 0.0) -> list[str]:
    """The Hydra multirun of ``seeds`` (default: every pending trial) of ``plan``."""
    chosen = [t.seed for t in plan.pending] if seeds is None else list(seeds)
    limit = [f"time_limit_min={time_limit_min:g}"] if time_limit_min > 0 else []
    return [sys.executable, "-m", "plls_bench", "-m", f"+experiment={plan.experiment}",
            f"budget={profile}", f"seed={','.join(map(str, chosen))}", f"runs_dir={runs_dir}",
            *plan.overrides, *limit, *overrides]


def run_plans(plans: list[PresetPlan], profile: str, runs_dir: str, overrides: list[str], jobs: int = 1,
              per_trial: bool = True, time_limit_min: float = 0.0, stop_after_min: float = 0.0,
              order: str = "shortest", launcher: str = "joblib") -> list[str]:
    """Launch each preset's pending trials, stage by stage; returns the presets with a failed trial.
    ``per_trial``: the queue of one-trial multiruns, ``jobs`` at a time in ``order``
    (:data:`QUEUE_ORDERS`), ending by ``stop_after_min`` minutes from now (0: no deadline; the
    ``launcher``'s threads per trial size what a trial needs left to start); else one multirun per
    preset (SLURM). ``time_limit_min``: each trial's own limit (0: none)."""
    deadline = time.monotonic() + 60.0 * stop_after_min if stop_after_min > 0 else None
    failed: list[str] = []
    for stage_plans in stages(plans):
        for plan in stage_plans:
            if not plan.pending:
                print(f"[reproduce] {plan.label}: all {len(plan.trials)} trial(s) already done", flush=True)
        todo = [p for p in stage_plans if p.pending]
        if per_trial:
            failed += _run_queued(todo, profile, runs_dir, overrides, jobs, time_limit_min, deadline, order, launcher)
            continue
        for plan in todo:
            start = time.perf_counter()
            code = subprocess.run(multirun_command(plan, profile, runs_dir, overrides,
                                                   time_limit_min=time_limit_min)).returncode
            failed += _report(plan, [code], time.perf_counter() - start)
    return failed


def stages(plans: list[PresetPlan]) -> list[list[PresetPlan]]:
    """``plans`` (in plan order) grouped into the stages that run one after another: the runners'
    :attr:`plls_bench.pipeline.runner_registry.RunnerSpec.order`."""
    return [list(stage) for _, stage in itertools.groupby(plans, key=lambda p: runner_spec(p.runner).order)]


def queue_order(plans: list[PresetPlan], order: str = "shortest") -> list[tuple[int, Trial]]:
    """One stage's pending trials as ``(plan index, trial)`` in the order the queue starts them:
    ``shortest`` estimated time left first, so trials end, and can be recorded, as soon as they can,
    or ``longest`` first, so the last one ends soonest (trials of 44, 34 and 22 CNN PPO iterations
    on 2 cores: 66 iterations of wall time shortest-first, 56 longest-first). Without an estimate for
    every trial (a rate never measured), the fraction of its own training left decides, so
    ``shortest`` puts trials that resume from a checkpoint before the fresh ones. Ties keep plan
    order. Time, not the fraction left, orders a stage of several presets: 20% of a 3 CPU-hour state
    SAC trial is over before 70% of a 10 CPU-hour CNN PPO trial."""
    if order not in QUEUE_ORDERS:
        raise ValueError(f"queue order {order!r} is not one of {', '.join(QUEUE_ORDERS)}")
    pending = [(i, t) for i, p in enumerate(plans) for t in p.pending]
    longest = order == "longest"  # sorted(reverse=True) keeps ties in plan order too
    if all(t.seed in plans[i].trial_seconds for i, t in pending):
        return sorted(pending, key=lambda item: plans[item[0]].trial_seconds[item[1].seed], reverse=longest)
    return sorted(pending, key=lambda item: item[1].remaining, reverse=longest)


@dataclass(frozen=True)
class Slot:
    """Where the queue puts one pending trial, by the estimates: seconds from the launch."""
    label: str       # its preset (and variant)
    trial: Trial
    start: float
    end: float
    least_left: float  # seconds it needs left to the deadline to start (start_minutes)


def trial_threads(plan: PresetPlan, trial: Trial, launcher: str) -> int:
    """The cores a trial keeps busy, which turn its estimated CPU seconds into wall seconds: one
    under ``joblib`` (:func:`launcher_overrides` gives each trial one torch thread); otherwise a
    policy learner's own ``torch_threads`` (0: torch's default, one per core). Other runners count
    one: collection is bound by its env, and V_s / V_a fits and studies set their own threads. The
    rates are CPU seconds at the preset's threads (bench/throughput.json), so a learner given both
    cores of a 2-core machine ends in about half its CPU time (pixel DBC alone at 2 threads:
    0.57 s per agent step measured against 0.63 s by this estimate)."""
    if launcher == "joblib" or not runner_spec(plan.runner).trains_policy:
        return 1
    return trial.cfg.torch_threads if trial.cfg.torch_threads > 0 else (os.cpu_count() or 1)


def simulate_queue(plans: list[PresetPlan], jobs: int, order: str = "shortest", launcher: str = "joblib") -> list[Slot]:
    """The queue over ``plans`` as estimated: each stage's trials started in :func:`queue_order` on
    the first of ``jobs`` slots to free, stages one after another, each trial taking its estimated
    seconds (``PresetPlan.trial_seconds``; unknown ones count 0) over its :func:`trial_threads`
    under ``launcher``."""
    slots, stage_start = [], 0.0
    for stage_plans in stages(plans):
        free = [stage_start] * max(jobs, 1)  # the time each job frees up, a heap
        for i, trial in queue_order(stage_plans, order):
            start = heapq.heappop(free)
            cpu_seconds = stage_plans[i].trial_seconds.get(trial.seed, 0.0)
            end = start + cpu_seconds / trial_threads(stage_plans[i], trial, launcher)
            heapq.heappush(free, end)
            least_left = 60.0 * start_minutes(stage_plans[i], trial, launcher)
            slots.append(Slot(stage_plans[i].label, trial, start, end, least_left))
        stage_start = max(free)
    return slots


def estimated_wall_seconds(plans: list[PresetPlan], jobs: int, order: str = "shortest",
                           launcher: str = "joblib") -> float:
    """Wall-clock seconds of the queue (:func:`simulate_queue`). Not total / jobs: 3 trials on 2
    jobs leave the last to run alone, so the longest chain, not the average, sets the wall time."""
    return max((slot.end for slot in simulate_queue(plans, jobs, order, launcher)), default=0.0)


def deadline_outlook(plans: list[PresetPlan], jobs: int, stop_after_min: float,
                     order: str = "shortest", launcher: str = "joblib") -> list[str]:
    """What ``--stop-after-min`` leaves by the estimates: how many trials end, are stopped at a
    checkpoint (each with about how far its training gets) or never start."""
    if any(p.missing_rates for p in plans):
        return [f"by --stop-after-min {stop_after_min:g}: no outlook, some trials have no estimate"]
    deadline = 60.0 * stop_after_min
    slots = simulate_queue(plans, jobs, order, launcher)
    late = [s for s in slots if s.start > deadline - s.least_left]
    stopped = [s for s in slots if s not in late and s.end > deadline]
    lines = [f"by --stop-after-min {stop_after_min:g}: {len(slots) - len(late) - len(stopped)} trial(s) end, "
             f"{len(stopped)} stop at a checkpoint, {len(late)} do not start (estimates)"]
    for s in stopped:
        ran = (deadline - s.start) / (s.end - s.start)
        reached = 1.0 - s.trial.remaining * (1.0 - ran)
        lines.append(f"  stops: {s.label} seed={s.trial.seed} before about {100 * reached:.0f}% of its "
                     f"training (its last checkpoint by then)")
    return lines


def _run_queued(plans: list[PresetPlan], profile: str, runs_dir: str, overrides: list[str], jobs: int,
                time_limit_min: float, deadline: float | None, order: str = "shortest",
                launcher: str = "joblib") -> list[str]:
    """Every pending trial of ``plans`` as its own multirun, ``jobs`` at a time, in
    :func:`queue_order`."""
    pending = queue_order(plans, order)

    def launch_of(i: int, trial: Trial) -> Launch:
        def argv() -> list[str] | None:
            limit = _limit_at_start(time_limit_min, deadline, start_minutes(plans[i], trial, launcher))
            if limit is None:
                return None
            return multirun_command(plans[i], profile, runs_dir, overrides, [trial.seed], limit)
        return argv

    start = time.perf_counter()
    codes = run_queue([((i, t.seed), launch_of(i, t)) for i, t in pending], jobs)
    failed: list[str] = []
    for i, plan in enumerate(plans):
        failed += _report(plan, [codes[(i, t.seed)] for t in plan.pending], time.perf_counter() - start)
    return failed


def _limit_at_start(time_limit_min: float, deadline: float | None,
                    least_minutes: float = MIN_START_MINUTES) -> float | None:
    """A trial's ``time_limit_min`` if it starts now: its own, or the time left to the deadline if
    shorter; None if less than ``least_minutes`` is left (too little to reach a checkpoint)."""
    if deadline is None:
        return time_limit_min
    left = (deadline - time.monotonic()) / 60.0
    if left < least_minutes:
        return None
    return min(time_limit_min, left) if time_limit_min > 0 else left


def _report(plan: PresetPlan, codes: list[int | None], seconds: float) -> list[str]:
    """Print a preset's outcome (a None code: never started, the deadline came first); returns its
    label if a trial's multirun failed. ``codes``: one per pending trial, or one for all of them."""
    stopped = [t.seed for t in plan.pending if (Run(t.run_dir).read_status() or {}).get("state") == STATUS_STOPPED]
    bad = _failures(plan, codes, set(stopped))
    status = "ok" if not bad else f"FAILED (exit {bad[0]})"
    ran = sum(c is not None for c in codes)
    note = (f", seed(s) {', '.join(map(str, stopped))} stopped early (time limit or SIGTERM; run again "
            f"to resume)" if stopped else "")
    if ran < len(codes):
        note += (f", {len(codes) - ran} not started (--stop-after-min reached, or too close to reach a "
                 f"checkpoint; run again to start them)")
    print(f"[reproduce] {plan.label}: {status}; ran {ran} trial(s), "
          f"{len(plan.trials) - len(plan.pending)} already done, {seconds:.0f}s{note}", flush=True)
    return [plan.label] if bad else []


def _failures(plan: PresetPlan, codes: list[int | None], stopped_seeds: set[int]) -> list[int]:
    """The non-zero exits that are failures: not those of the trials in ``stopped_seeds``, whose
    status reads ``stopped`` (SIGTERM stops a trial at its checkpoint with exit 143; the next
    launch resumes it)."""
    if len(codes) != len(plan.pending):  # one multirun for the whole preset: its trials are not told apart
        return [c for c in codes if c not in (0, None)]
    return [c for trial, c in zip(plan.pending, codes) if c not in (0, None) and trial.seed not in stopped_seeds]


def run_queue(commands: list[tuple[Hashable, Launch]], jobs: int) -> dict[Hashable, int | None]:
    """Run ``(key, launch)`` commands, at most ``jobs`` at once, each started as soon as a slot
    frees: ``launch()`` gives its argv when it starts, or None to skip it. Returns each key's exit
    status (None: skipped). Ctrl-C starts nothing more, lets the running ones stop (see
    ``INTERRUPT_GRACE_SECONDS``) and re-raises; so does :class:`Terminated`, after passing SIGTERM
    on to them at once."""
    queue, running, codes = deque(commands), {}, {}
    try:
        while queue or running:
            while queue and len(running) < jobs:
                key, launch = queue.popleft()
                argv = launch()
                if argv is None:
                    codes[key] = None
                else:
                    running[subprocess.Popen(argv)] = key
            ended = [proc for proc in running if proc.poll() is not None]
            for proc in ended:
                codes[running.pop(proc)] = proc.returncode
            if not ended:
                time.sleep(POLL_SECONDS)
    except KeyboardInterrupt:
        _stop(list(running), grace_s=INTERRUPT_GRACE_SECONDS)
        raise
    except Terminated:  # reproduce alone was sent SIGTERM (reproduce's sigterm_raises): pass it on
        _stop(list(running), grace_s=0.0)
        raise
    return codes


def _stop(procs: list[subprocess.Popen], grace_s: float) -> None:
    """Wait up to ``grace_s`` for ``procs`` to end by themselves, then SIGTERM the rest (a trial
    stops at a resumable point, status ``stopped``) and wait for them."""
    deadline = time.monotonic() + grace_s
    for proc in procs:
        try:
            proc.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGTERM)
    for proc in procs:
        proc.wait()
