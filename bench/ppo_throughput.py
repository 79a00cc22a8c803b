"""Env steps per second of PPO methods at their presets' settings (default: MountainCar, Table 1).

    .venv/bin/python bench/ppo_throughput.py                       # both MountainCar methods
    .venv/bin/python bench/ppo_throughput.py --presets carracing_ppo carracing_plls_ppo --iterations 2
    .venv/bin/python bench/ppo_throughput.py --presets carracing_plls_ppo carracing_ppo_vs --backends gymnasium envpool

Each preset's training vector env and SB3 model are built exactly as the ``ppo`` runner builds
them (``budget=quick``: the paper's Table 1 / Table 2 PPO settings) from V_s / V_a artifacts that
must already exist under ``--runs`` (nothing is trained here), one warm-up iteration runs,
then ``--iterations`` PPO iterations (rollout + update, no evaluation) are timed. Prints the
command and the machine, and rewrites this script's section of ``docs/benchmarks.md``.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import torch
from stable_baselines3 import PPO

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.benchmarks_md import announce, finish_section  # noqa: E402
from bench.representations import TINY_REPR, prepare_representations  # noqa: E402
from plls_bench.config.tasks import ENV_BACKENDS  # noqa: E402
from plls_bench.core.seeding import derive_seeds, seed_everything  # noqa: E402
from plls_bench.repr.store import load_representations  # noqa: E402
from plls_bench.rundirs.composition import compose  # noqa: E402
from plls_bench.train.ppo import EpisodeStats  # noqa: E402
from plls_bench.train.ppo_model import build_vec_env, new_model  # noqa: E402

SECTION = "ppo_throughput"


Sample = tuple[float, float, float, float]  # rollout s, total s, rollout CPU s, total CPU s of one PPO iteration


def build(preset: str, budget: str, runs_dir: str, overrides: Sequence[str] = ()) -> tuple[Any, PPO, int]:
    """The preset's training vector env and SB3 model, built exactly as the ``ppo`` runner builds
    them, and the env steps of one iteration. ``overrides`` apply after the preset's."""
    cfg = compose([f"+experiment={preset}", f"budget={budget}", f"runs_dir={runs_dir}", "progress=false",
                   *overrides])
    assert cfg.algo.ppo is not None
    if cfg.torch_threads > 0:
        torch.set_num_threads(cfg.torch_threads)
    seed = derive_seeds(cfg.seed, cfg.data_seed).train
    seed_everything(seed)
    venv = build_vec_env(cfg, cfg.algo.ppo.n_envs, seed, load_representations(cfg))  # never trains
    return venv, new_model(cfg, venv), cfg.algo.ppo.steps_per_iteration


def iteration(model: PPO, steps: int, stats: EpisodeStats) -> Sample:
    """One PPO iteration (rollout, then the update; no evaluation), timed."""
    start, start_cpu = time.perf_counter(), time.process_time()
    model.learn(steps, callback=stats, reset_num_timesteps=False, log_interval=None)
    return (stats.rollout_end - start, time.perf_counter() - start, stats.rollout_end_cpu - start_cpu,
            time.process_time() - start_cpu)


def summarize(steps: int, samples: list[Sample]) -> dict[str, float]:
    """Medians of ``samples`` as seconds and env steps per second (wall and CPU)."""
    r, t, rc, c = (statistics.median(column) for column in zip(*samples))
    return {"steps": steps, "rollout_s": r, "update_s": t - r, "rollout_sps": steps / r, "sps": steps / t,
            "cpu_s": c, "cpu_sps": steps / c, "rollout_cpu_sps": steps / rc, "threads": torch.get_num_threads()}


def measure(preset: str, budget: str, iterations: int, runs_dir: str,
            overrides: Sequence[str] = ()) -> dict[str, float]:
    """Median seconds of rollout and update per PPO iteration, and env steps per second.
    ``overrides`` (e.g. a shorter ``algo.ppo.n_steps``) are applied after the preset's."""
    venv, model, steps = build(preset, budget, runs_dir, overrides)
    stats = EpisodeStats()
    try:
        samples = [iteration(model, steps, stats) for _ in range(iterations + 1)][1:]  # the first warms up
    finally:
        venv.close()
    return summarize(steps, samples)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--presets", nargs="+", default=["mountaincar_ppo", "mountaincar_plls_ppo"])
    parser.add_argument("--budget", default="quick", help="budget whose PPO settings are used")
    parser.add_argument("--iterations", type=int, default=3, help="timed PPO iterations per preset")
    parser.add_argument("--runs", default="results/runs", help="runs_dir (V_s / V_a artifacts are reused)")
    parser.add_argument("--tiny-repr", action="store_true",
                        help="a tiny V_s / V_a (built first, visibly): weights do not change the speed")
    parser.add_argument("--backends", nargs="+", default=None, choices=ENV_BACKENDS,
                        help="measure each preset on these env.backend values (default: the profile's)")
    parser.add_argument("--no-write", action="store_true", help="print only, leave docs/benchmarks.md alone")
    args = parser.parse_args(argv)
    command = announce("ppo_throughput.py", argv)
    rows = []
    for preset, backend in [(p, b) for p in args.presets for b in (args.backends or [None])]:
        overrides = [*(TINY_REPR if args.tiny_repr else ()), *([f"env.backend={backend}"] if backend else [])]
        if args.tiny_repr:
            prepare_representations(compose([f"+experiment={preset}", f"budget={args.budget}",
                                             f"runs_dir={args.runs}", "progress=false", *overrides]))
        m = measure(preset, args.budget, args.iterations, args.runs, overrides)
        label = f"`{preset}`" + (f" ({backend})" if backend else "")
        rows.append(f"| {label} | {m['steps']} | {m['rollout_s']:.2f} | {m['update_s']:.2f} | "
                    f"{m['rollout_sps']:.0f} | **{m['sps']:.0f}** | {m['cpu_s']:.2f} | {m['cpu_sps']:.0f} | "
                    f"{m['threads']} |")
        print(rows[-1], flush=True)
    finish_section(
        SECTION, f"PPO env steps per second (`bench/ppo_throughput.py`, budget={args.budget})", command,
        f"Median of {args.iterations} PPO iterations after one warm-up; one iteration = n_envs x n_steps "
        "env steps, rollout (env steps, policy forward, V_s / V_a forward) then the SB3 update "
        "(n_epochs over minibatches). No evaluation. CPU s is the process's CPU time per iteration "
        "(in-process vector env): steps per CPU-second are less disturbed by other load than steps/s.",
        ["preset", "env steps / iteration", "rollout s", "update s", "rollout steps/s", "steps/s",
         "CPU s / iteration", "steps per CPU-s", "torch threads"], rows, write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
