"""DBC update throughput (updates per second) and acting throughput (env steps per second).

    nice -n 10 .venv/bin/python bench/dbc_throughput.py                      # cheetah_dbc, budget=quick
    nice -n 10 .venv/bin/python bench/dbc_throughput.py --threads 1 2 --updates 20
    nice -n 10 .venv/bin/python bench/dbc_throughput.py --threads 1 --layouts contiguous channels_last
    nice -n 10 .venv/bin/python bench/dbc_throughput.py --threads 1 --layouts contiguous channels_last \
        --precisions fp32 bf16

The env and agent are built as the ``dbc`` runner builds them (``budget=quick``: the reference
launcher's batch size 128 and hidden size 1024), from a V_a artifact that must already exist
under ``--runs`` for PL-LS presets (nothing is trained here). Acting: ``--steps`` agent steps of the training
VecEnv (render, frame stack, stochastic policy forward, replay insert; no updates), reported in
env steps (frames, counting the preset's action repeat) per second. Updates: median time of ``--updates`` full DBC
updates (critic, bisimulation/transition/reward, actor and temperature on even steps, targets)
on minibatches sampled from the replay filled by the acting phase. ``--layouts``: ``channels_last``
is the suite's (every conv trunk runs in its weights' layout, ``plls_bench/repr/pixel_trunk.py``);
``contiguous`` converts the built agent's modules back before any update, the layout before that
change. ``--precisions`` sets the top-level ``precision`` key (``bf16``: autocast around the conv
trunks; DBC failed the bf16 null comparison, so this is speed only). Prints the command and the
machine, and rewrites this script's section of ``docs/benchmarks.md``.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.benchmarks_md import announce, finish_section  # noqa: E402
from plls_bench.config import PRECISIONS  # noqa: E402
from plls_bench.core.seeding import seed_everything  # noqa: E402
from plls_bench.repr.store import load_representations  # noqa: E402
from plls_bench.rundirs.composition import compose  # noqa: E402
from plls_bench.rundirs.run_dir import Run  # noqa: E402
from plls_bench.train.dbc import DBCTrainer  # noqa: E402

SECTION = "dbc_throughput"
LAYOUT_SECTION = "dbc_layouts"
LAYOUTS = {"contiguous": torch.contiguous_format, "channels_last": torch.channels_last}


def build_trainer(preset: str, budget: str, runs_dir: str, overrides: Sequence[str] = ()) -> DBCTrainer:
    """A set-up ``DBCTrainer`` as the ``dbc`` runner builds it; ``overrides`` apply after the preset's."""
    cfg = compose([f"+experiment={preset}", f"budget={budget}", f"runs_dir={runs_dir}", "progress=false",
                   *overrides])
    seed_everything(0)
    # load_representations never trains: the V_a must exist (bench/throughput.py prepares it)
    trainer = DBCTrainer(cfg, Run(Path(runs_dir) / "bench" / preset), load_representations(cfg))
    trainer.setup()
    return trainer


def measure(preset: str, budget: str, threads: int, steps: int, updates: int, runs_dir: str,
            overrides: Sequence[str] = (), layout: str = "channels_last") -> dict[str, float]:
    """Acting env steps/s and seconds per update; ``overrides`` apply after the preset's."""
    torch.set_num_threads(threads)
    trainer = build_trainer(preset, budget, runs_dir, overrides)
    for module in trainer.agent.modules().values():  # in place: the optimisers keep their parameters
        module.to(memory_format=LAYOUTS[layout])
    cfg = trainer.cfg
    try:
        obs = trainer.train_env.reset()
        trainer.replay.start_episode(obs[0])
        start, start_cpu = time.perf_counter(), time.process_time()
        for i in range(steps):  # steps from init_steps on: the policy acts, as after init
            obs, _, _ = trainer.step(obs, cfg.algo.dbc.init_steps + i, updates=False)
        acting, acting_cpu = time.perf_counter() - start, time.process_time() - start_cpu
        times, cpu = [], []
        for i in range(updates + 2):  # two warm-up updates
            start, start_cpu = time.perf_counter(), time.process_time()
            trainer.agent.update(trainer.replay.sample(cfg.algo.dbc.batch_size, trainer.rng, trainer.device), i)
            times.append(time.perf_counter() - start)
            cpu.append(time.process_time() - start_cpu)
        per_update, cpu_per_update = statistics.median(times[2:]), statistics.median(cpu[2:])
    finally:
        trainer.train_env.close()
        trainer.eval_env.close()
    return {"env_sps": steps * cfg.env.action_repeat / acting, "update_s": per_update, "ups": 1.0 / per_update,
            "env_cpu_sps": steps * cfg.env.action_repeat / acting_cpu, "cpu_s": cpu_per_update,
            "batch": cfg.algo.dbc.batch_size, "bytes": trainer.replay.bytes_per_slot(),
            "reference_bytes": trainer.replay.reference_bytes_per_transition()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--presets", nargs="+", default=["cheetah_dbc"])
    parser.add_argument("--budget", default="quick", help="budget whose DBC settings are used")
    parser.add_argument("--threads", nargs="+", type=int, default=[1, 2], help="torch intra-op threads")
    parser.add_argument("--layouts", nargs="+", default=["channels_last"], choices=list(LAYOUTS))
    parser.add_argument("--precisions", nargs="+", default=["fp32"], choices=PRECISIONS,
                        help="top-level precision (bf16: autocast around the conv trunks)")
    parser.add_argument("--steps", type=int, default=100, help="timed agent steps of acting")
    parser.add_argument("--updates", type=int, default=10, help="timed updates (after 2 warm-up)")
    parser.add_argument("--runs", default="/tmp/plls_bench_dbc_bench", help="runs_dir (V_a artifacts)")
    parser.add_argument("--no-write", action="store_true", help="print only, leave docs/benchmarks.md alone")
    args = parser.parse_args(argv)
    command = announce("dbc_throughput.py", argv)
    rows = []
    for preset in args.presets:
        for threads in args.threads:
            base = None  # contiguous fp32's CPU s per update, when measured first
            for precision in args.precisions:
                for layout in args.layouts:
                    m = measure(preset, args.budget, threads, args.steps, args.updates, args.runs,
                                [f"precision={precision}"], layout=layout)
                    base = m["cpu_s"] if (layout, precision) == ("contiguous", "fp32") else base
                    ratio = f"{base / m['cpu_s']:.2f}x" if base else "—"
                    rows.append(f"| `{preset}` | {threads} | {layout} | {precision} | {m['env_sps']:.1f} | "
                                f"{m['batch']} | "
                                f"{m['update_s']:.2f} | {m['cpu_s']:.2f} | {ratio} | **{m['ups']:.2f}** | "
                                f"{m['bytes']:,} / {m['reference_bytes']:,} |")
                    print(rows[-1], flush=True)
    # a layout or precision comparison is a section of its own: the per-thread table of the suite's settings stays
    suite_settings = args.layouts == ["channels_last"] and args.precisions == ["fp32"]
    section, what = (SECTION, "") if suite_settings else (LAYOUT_SECTION, " per memory layout and precision")
    finish_section(
        section, f"DBC updates and env steps per second{what} (`bench/dbc_throughput.py`, budget={args.budget})",
        command, f"Acting: {args.steps} agent steps (render, stochastic policy, replay insert; no updates), in env "
        f"steps (frames) per second. Updates: median of {args.updates} full DBC updates after 2 warm-up. "
        "CPU s / update is the process time (all threads), less sensitive than wall time to other "
        "processes on a shared machine. Replay bytes per transition: this suite's frame replay / the "
        "reference's layout.",
        ["preset", "torch threads", "layout", "precision", "acting env steps/s", "batch", "s / update",
         "CPU s / update", "update vs contiguous fp32 (CPU s)", "updates/s",
         "replay bytes"], rows, write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
