"""What ``retain_freed_memory`` (plls_bench/core/malloc_retain.py) saves a DBC update: CPU s and page faults per
update with glibc's default memory handling and with freed memory kept in the heap, in one run.

    nice -n 10 .venv/bin/python bench/malloc_retain.py                  # cheetah_dbc, budget=quick
    nice -n 10 .venv/bin/python bench/malloc_retain.py --repeats 3 --no-write

The setting is process-wide and cannot be undone, so each setting runs in child processes of this
script, alternating settings ``--repeats`` times so that load drifting over the run reaches all of them:
``default`` (glibc as it comes), ``retain`` (the suite's default: ``retain_freed_memory()`` before
the agent is built, as the runner applies it), and the same two with torch's own
``THP_MEM_ALLOC_ENABLE=1`` (large tensors aligned and advised as transparent huge pages; torch reads
it once, at its first allocation, so only the environment can set it). In each child one DBC agent
(``bench/dbc_throughput.py``'s construction) updates ``--rounds`` times on one fixed minibatch after
two warm-up updates. Per update: CPU s (process time, all threads) and minor page faults (each one a
fresh page the kernel zeroes). Peak RSS is the child's, whole life. The load average says how busy
the cores were; compare the settings as ratios, measured in the same run.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.benchmarks_md import announce, finish_section, machine  # noqa: E402
from bench.dbc_threads import add_child_arguments, filled_batch  # noqa: E402
from bench.dbc_throughput import build_trainer  # noqa: E402
from plls_bench.core.malloc_retain import retain_freed_memory  # noqa: E402

SECTION = "malloc_retain"
SETTINGS = ("default", "retain", "default+thp", "retain+thp")


def child(setting: str, preset: str, budget: str, steps: int, rounds: int, runs_dir: str) -> dict[str, list[float]]:
    """``{"cpu_s": [...], "faults": [...], "peak_rss_mib": [x]}`` of ``rounds`` single updates."""
    torch.set_num_threads(1)
    if setting.startswith("retain"):  # before the agent is built, as the runner applies it
        retain_freed_memory()
    trainer = build_trainer(preset, budget, runs_dir)
    try:
        batch = filled_batch(trainer, steps)
        cpu, faults = [], []
        for r in range(rounds + 2):  # two warm-up updates
            start_cpu, start_faults = time.process_time(), resource.getrusage(resource.RUSAGE_SELF).ru_minflt
            trainer.agent.update(batch, r)
            if r >= 2:
                cpu.append(time.process_time() - start_cpu)
                faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - start_faults)
    finally:
        trainer.train_env.close()
        trainer.eval_env.close()
    return {"cpu_s": cpu, "faults": faults, "peak_rss_mib": [resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024]}


def run_child(setting: str, args: argparse.Namespace) -> dict[str, list[float]]:
    """One child process for ``setting``; its measurements."""
    env = {k: v for k, v in os.environ.items() if k != "THP_MEM_ALLOC_ENABLE"}
    if setting.endswith("+thp"):
        env["THP_MEM_ALLOC_ENABLE"] = "1"
    command = [sys.executable, __file__, "--child", setting, "--preset", args.preset, "--budget", args.budget,
               "--steps", str(args.steps), "--rounds", str(args.rounds), "--runs", args.runs]
    out = subprocess.run(command, env=env, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def rows(results: dict[str, dict[str, list[float]]]) -> list[str]:
    """Markdown rows: setting, median CPU s / update, range, faults / update, peak RSS, vs default."""
    base = statistics.median(results["default"]["cpu_s"])
    out = []
    for setting, m in results.items():
        cpu = statistics.median(m["cpu_s"])
        out.append(f"| {setting} | **{cpu:.2f}** | {min(m['cpu_s']):.2f} - {max(m['cpu_s']):.2f} | "
                   f"{statistics.median(m['faults']):,.0f} | {max(m['peak_rss_mib']):,.0f} | {base / cpu:.2f}x |")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_child_arguments(parser, 4, "timed updates per child (after 2 warm-up)")
    parser.add_argument("--repeats", type=int, default=2, help="children per setting, settings alternating")
    parser.add_argument("--settings", nargs="+", default=list(SETTINGS), choices=SETTINGS)
    parser.add_argument("--child", choices=SETTINGS, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.steps < 2 or args.rounds < 1 or args.repeats < 1 or "default" not in args.settings:
        parser.error("--steps must be at least 2, --rounds and --repeats at least 1, and --settings hold default")
    if args.child:
        print(json.dumps(child(args.child, args.preset, args.budget, args.steps, args.rounds, args.runs)))
        return 0
    command = announce("malloc_retain.py", argv)
    results: dict[str, dict[str, list[float]]] = {s: {"cpu_s": [], "faults": [], "peak_rss_mib": []}
                                                  for s in args.settings}
    for repeat in range(args.repeats):
        for setting in args.settings:
            for key, values in run_child(setting, args).items():
                results[setting][key].extend(values)
            print(f"{setting} (repeat {repeat + 1}): CPU s {results[setting]['cpu_s'][-args.rounds:]}  "
                  f"({machine()})", flush=True)
    table = rows(results)
    print("\n".join(table))
    finish_section(
        SECTION, f"DBC update with freed memory kept in the heap (`bench/malloc_retain.py`, `{args.preset}`, "
        f"budget={args.budget})", command,
        f"One fixed minibatch, {args.rounds} updates per child after two warm-up, {args.repeats} children per "
        "setting, settings alternating. `retain`: `retain_freed_memory()` (glibc `M_MMAP_MAX=0`, no heap "
        "trimming; the suite's default). `+thp`: torch's `THP_MEM_ALLOC_ENABLE=1` in the child's environment. "
        "Faults: minor page faults per update (fresh pages the kernel zeroes). CPU s: process time of all "
        "threads, medians over every child of the setting.",
        ["setting", "CPU s / update (median)", "range", "page faults / update", "peak RSS MiB",
         "default / setting (CPU s)"], table, write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
