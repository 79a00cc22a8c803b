"""Why a DBC update at 2 torch threads can be slower than at 1: wall vs CPU time per update, per
OpenMP wait policy, in one run.

    nice -n 10 .venv/bin/python bench/dbc_threads.py                  # cheetah_dbc, budget=quick
    nice -n 10 .venv/bin/python bench/dbc_threads.py --rounds 5 --no-write

The OpenMP runtime reads ``OMP_WAIT_POLICY`` once, when torch loads it, so each policy runs in a
child process of this script (the variable unset: libgomp's default, which spins a while before
sleeping; ``PASSIVE``: waiting threads sleep at once). In each child one DBC agent
(``bench/dbc_throughput.py``'s construction) updates on one fixed minibatch sampled from a replay
filled by ``--steps`` acting steps, alternating 1 and 2 intra-op threads over ``--rounds`` rounds
after one warm-up each. CPU s is the process time of all threads: if the second thread did useful
work, CPU s would stay near the 1-thread figure while wall s fell; CPU s that grows while wall s
does not is time the threads spend waiting for each other (spinning, or the scheduler running
another process on the core one of them needs). The load average says how busy the cores were.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from baselines.dbc.agent import Batch  # noqa: E402
from bench.benchmarks_md import announce, finish_section, machine  # noqa: E402
from bench.dbc_throughput import build_trainer  # noqa: E402
from plls_bench.train.dbc import DBCTrainer  # noqa: E402

SECTION = "dbc_threads"
POLICIES = ("", "PASSIVE")  # "": OMP_WAIT_POLICY unset (what every run of the suite gets)
THREADS = (1, 2)


def child(preset: str, budget: str, steps: int, rounds: int, runs_dir: str) -> dict[str, list[list[float]]]:
    """``{threads: [[wall s, CPU s], ...]}`` of single updates, threads interleaved per round."""
    torch.set_num_threads(1)
    trainer = build_trainer(preset, budget, runs_dir)
    try:
        batch = filled_batch(trainer, steps)
        times: dict[str, list[list[float]]] = {str(t): [] for t in THREADS}
        for r in range(rounds + 1):  # round 0 warms up each thread count
            for threads in THREADS:
                torch.set_num_threads(threads)
                start, start_cpu = time.perf_counter(), time.process_time()
                trainer.agent.update(batch, r)
                if r:
                    times[str(threads)].append([time.perf_counter() - start, time.process_time() - start_cpu])
    finally:
        trainer.train_env.close()
        trainer.eval_env.close()
    return times


def filled_batch(trainer: DBCTrainer, steps: int) -> Batch:
    """One minibatch from the replay after ``steps`` acting steps (the policy acts, no updates)."""
    dbc = trainer.cfg.algo.dbc
    obs = trainer.train_env.reset()
    trainer.replay.start_episode(obs[0])
    for i in range(steps):
        obs, _, _ = trainer.step(obs, dbc.init_steps + i, updates=False)
    return trainer.replay.sample(dbc.batch_size, trainer.rng, trainer.device)


def add_child_arguments(parser: argparse.ArgumentParser, rounds: int, rounds_help: str) -> None:
    """The options a parent passes on to its child processes, shared by the DBC update benches."""
    parser.add_argument("--preset", default="cheetah_dbc")
    parser.add_argument("--budget", default="quick", help="budget whose DBC settings are used")
    parser.add_argument("--steps", type=int, default=30, help="acting steps that fill the replay")
    parser.add_argument("--rounds", type=int, default=rounds, help=rounds_help)
    parser.add_argument("--runs", default="/tmp/plls_bench_dbc_bench", help="runs_dir (V_a artifacts)")
    parser.add_argument("--no-write", action="store_true", help="print only, leave docs/benchmarks.md alone")


def run_policy(policy: str, args: argparse.Namespace) -> dict[str, list[list[float]]]:
    """One child process with ``OMP_WAIT_POLICY=policy`` (unset for ""); its measurements."""
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    if policy:
        env["OMP_WAIT_POLICY"] = policy
    command = [sys.executable, __file__, "--child", "--preset", args.preset, "--budget", args.budget,
               "--steps", str(args.steps), "--rounds", str(args.rounds), "--runs", args.runs]
    out = subprocess.run(command, env=env, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def rows(results: dict[str, dict[str, list[list[float]]]]) -> list[str]:
    """Markdown rows: policy, threads, median wall s, median CPU s, CPU / wall, vs 1 thread."""
    out = []
    for policy, times in results.items():
        base = statistics.median(w for w, _ in times["1"])
        for threads, pairs in times.items():
            wall, cpu = statistics.median(w for w, _ in pairs), statistics.median(c for _, c in pairs)
            out.append(f"| {policy or 'unset (default)'} | {threads} | **{wall:.2f}** | {min(w for w, _ in pairs):.2f}"
                       f" - {max(w for w, _ in pairs):.2f} | {cpu:.2f} | {cpu / wall:.2f} | {wall / base:.2f}x |")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_child_arguments(parser, 3, "timed updates per thread count (after 1 warm-up)")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.steps < 2 or args.rounds < 1:
        parser.error("--steps must be at least 2 and --rounds at least 1")
    if args.child:
        print(json.dumps(child(args.preset, args.budget, args.steps, args.rounds, args.runs)))
        return 0
    command = announce("dbc_threads.py", argv)
    results = {}
    for policy in POLICIES:
        results[policy] = run_policy(policy, args)
        print(f"OMP_WAIT_POLICY={policy or 'unset'}: {results[policy]}  ({machine()})", flush=True)
    table = rows(results)
    print("\n".join(table))
    finish_section(
        SECTION, f"DBC update at 1 and 2 torch threads, per OpenMP wait policy (`bench/dbc_threads.py`, "
        f"`{args.preset}`, budget={args.budget})", command,
        f"One fixed minibatch, {args.rounds} updates per thread count after one warm-up, 1 and 2 threads "
        "alternating; one child process per `OMP_WAIT_POLICY`. CPU s is the process time of all threads: "
        "a useful second thread keeps CPU s near the 1-thread figure and cuts wall s; CPU s that grows "
        "with no gain in wall s is waiting. CPU / wall near 1 at 2 threads means the process had one "
        "core's worth of time in all.",
        ["OMP_WAIT_POLICY", "threads", "wall s / update (median)", "range", "CPU s / update", "CPU / wall",
         "wall vs 1 thread"], table, write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
