"""Launching a plan's pending trials through Hydra multiruns: one per preset, or for ``--launcher
joblib`` one per trial from a queue that keeps ``--jobs`` trials running.

A preset whose pending trials do not divide by the job count would leave cores idle under one
multirun per preset (3 trials on 2 cores: the third runs alone), and so would a sweep whose
variants each have one trial left. The joblib queue starts the next pending trial of any preset
of the same stage as soon as a trial ends, trials that resume from a checkpoint first. Stages are
the runners' plan order (:attr:`plls_bench.runner_specs.RunnerSpec.order`): artifacts are built
before the presets that read them, as with one multirun per preset.
"""
from __future__ import annotations

import itertools
import signal
import subprocess
import sys
import time
from collections import deque
from collections.abc import Sequence

from plls_bench.plan import PresetPlan
from plls_bench.runner_specs import runner_spec
from plls_bench.runs import STATUS_STOPPED, Run

POLL_SECONDS = 0.5
# On Ctrl-C the trials get SIGINT from the terminal too; a trial still running after this long
# (reproduce alone was signalled) gets SIGTERM, which stops it at a resumable point (status stopped).
INTERRUPT_GRACE_SECONDS = 30.0


def launcher_overrides(launcher: str, jobs: int, extra: list[str]) -> list[str]:
    """Hydra overrides that select a launcher (conf/hydra/launcher/) for every multirun."""
    if launcher == "joblib":
        # each one-trial multirun runs in its own process (the basic launcher): --jobs processes
        # with one torch thread each do not oversubscribe the cores
        return ["torch_threads=1", *extra]
    if launcher == "slurm":
        return ["hydra/launcher=slurm", *extra]
    return list(extra)


def multirun_command(plan: PresetPlan, profile: str, runs_dir: str, overrides: list[str],
                     seeds: Sequence[int] | None = None) -> list[str]:
    """The Hydra multirun of ``seeds`` (default: every pending trial) of ``plan``."""
    chosen = [t.seed for t in plan.pending] if seeds is None else list(seeds)
    return [sys.executable, "-m", "plls_bench", "-m", f"+experiment={plan.experiment}",
            f"budget={profile}", f"seed={','.join(map(str, chosen))}", f"runs_dir={runs_dir}",
            *plan.overrides, *overrides]


def run_plans(plans: list[PresetPlan], profile: str, runs_dir: str, overrides: list[str],
              jobs: int = 1, per_trial: bool = False) -> list[str]:
    """Launch each preset's pending trials, stage by stage; returns the presets with a failed trial.
    ``per_trial``: one multirun per trial, ``jobs`` at a time (the joblib launcher's queue)."""
    failed: list[str] = []
    for _, stage in itertools.groupby(plans, key=lambda p: runner_spec(p.runner).order):
        stage_plans = list(stage)
        for plan in stage_plans:
            if not plan.pending:
                print(f"[reproduce] {plan.label}: all {len(plan.trials)} trial(s) already done", flush=True)
        todo = [p for p in stage_plans if p.pending]
        if per_trial:
            failed += _run_queued(todo, profile, runs_dir, overrides, jobs)
        else:
            for plan in todo:
                start = time.perf_counter()
                code = subprocess.run(multirun_command(plan, profile, runs_dir, overrides)).returncode
                failed += _report(plan, [code], time.perf_counter() - start)
    return failed


def _run_queued(plans: list[PresetPlan], profile: str, runs_dir: str, overrides: list[str],
                jobs: int) -> list[str]:
    """Every pending trial of ``plans`` as its own multirun, ``jobs`` at a time: trials that resume
    from a checkpoint first, least left first (they end, and can be recorded, soonest), then the
    fresh ones in plan order."""
    pending = [(i, t) for i, p in enumerate(plans) for t in p.pending]
    pending.sort(key=lambda item: item[1].remaining)  # stable: ties keep plan order
    commands = [((i, t.seed), multirun_command(plans[i], profile, runs_dir, overrides, [t.seed]))
                for i, t in pending]
    start = time.perf_counter()
    codes = run_queue(commands, jobs)
    failed: list[str] = []
    for i, plan in enumerate(plans):
        failed += _report(plan, [codes[(i, t.seed)] for t in plan.pending], time.perf_counter() - start)
    return failed


def _report(plan: PresetPlan, codes: list[int], seconds: float) -> list[str]:
    """Print a preset's outcome; returns its label if a trial's multirun failed."""
    bad = [c for c in codes if c != 0]
    status = "ok" if not bad else f"FAILED (exit {bad[0]})"
    stopped = [t.seed for t in plan.pending if (Run(t.run_dir).read_status() or {}).get("state") == STATUS_STOPPED]
    note = (f", seed(s) {', '.join(map(str, stopped))} stopped early (time_limit_min or SIGTERM; run again "
            f"to resume)" if stopped else "")
    print(f"[reproduce] {plan.label}: {status}; ran {len(plan.pending)} trial(s), "
          f"{len(plan.trials) - len(plan.pending)} already done, {seconds:.0f}s{note}", flush=True)
    return [plan.label] if bad else []


def run_queue(commands: list[tuple[object, list[str]]], jobs: int) -> dict[object, int]:
    """Run ``(key, argv)`` commands, at most ``jobs`` at once, each started as soon as a slot frees;
    returns each key's exit status. Ctrl-C starts nothing more, lets the running ones stop (see
    ``INTERRUPT_GRACE_SECONDS``) and re-raises."""
    queue, running, codes = deque(commands), {}, {}
    try:
        while queue or running:
            while queue and len(running) < jobs:
                key, argv = queue.popleft()
                running[subprocess.Popen(argv)] = key
            ended = [proc for proc in running if proc.poll() is not None]
            for proc in ended:
                codes[running.pop(proc)] = proc.returncode
            if not ended:
                time.sleep(POLL_SECONDS)
    except KeyboardInterrupt:
        _stop(list(running))
        raise
    return codes


def _stop(procs: list[subprocess.Popen]) -> None:
    deadline = time.monotonic() + INTERRUPT_GRACE_SECONDS
    for proc in procs:
        try:
            proc.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGTERM)
    for proc in procs:
        proc.wait()
