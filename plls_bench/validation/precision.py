"""Is bf16 within the noise PPO and DBC already live with? A null comparison, no learning runs.

``python -m plls_bench.validation.precision [--orders K] [--ppo-envs N --ppo-steps T
--ppo-epochs E --ppo-batch B] [--dbc-transitions M --dbc-updates U --dbc-batch B]
[--out results/analysis/precision_validation.md]``

From one fixed batch and the same initial weights (:mod:`plls_bench.validation.precision_runs`), the
update runs in fp32 with K minibatch orders and in bf16 with the same K orders. Each resulting
network is run (in its own precision) on held-out observations, and two networks' distance is
measured there: PPO's symmetrised KL between the Gaussian action distributions and the mean
|value difference|; DBC's mean |Q difference| (both critics), mean |mean-action difference| and
the encoder latent's relative L2 difference.

**The rule.** For each measure, with ``same_k = d(fp32_k, bf16_k)`` (k = 1..K) and
``cross_ij = d(fp32_i, fp32_j)`` (i < j): bf16 passes iff ``max_k same_k <= min_ij cross_ij``,
i.e. no bf16 network is further from its fp32 twin than any two fp32 networks trained on other
minibatch orders are from each other. A learner passes iff every one of its measures passes.
Defaults are the presets' sizes (budget=quick); the report states the sizes it ran at.
"""
from __future__ import annotations

import argparse
import itertools
import os
import platform
import shlex
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from plls_bench.core.atomic_files import atomic_write_bytes, atomic_write_json
from plls_bench.validation.precision_runs import Outputs, Sizes

Measure = Callable[[Outputs, Outputs], float]


# ------------------------------------------------------------------------------ distances (pure)
def gaussian_kl(mean_a: np.ndarray, std_a: np.ndarray, mean_b: np.ndarray, std_b: np.ndarray) -> float:
    """Symmetrised KL ``(KL(a||b) + KL(b||a)) / 2`` of diagonal Gaussians, summed over the action
    dimensions and averaged over observations; every array ``(N, A)``."""
    var_a, var_b = np.square(std_a), np.square(std_b)
    sq = np.square(mean_a - mean_b)
    ab = np.log(std_b / std_a) + (var_a + sq) / (2 * var_b) - 0.5
    ba = np.log(std_a / std_b) + (var_b + sq) / (2 * var_a) - 0.5
    return float(np.mean(np.sum(0.5 * (ab + ba), axis=-1)))


def mean_abs(a: np.ndarray, b: np.ndarray) -> float:
    """Mean absolute difference of two arrays of the same shape ``(N, ...)``."""
    return float(np.mean(np.abs(a - b)))


def relative_l2(a: np.ndarray, b: np.ndarray) -> float:
    """``mean_n ||a_n - b_n|| / mean_n (||a_n|| + ||b_n||) / 2`` for ``a``, ``b`` ``(N, D)``."""
    scale = 0.5 * (np.linalg.norm(a, axis=1) + np.linalg.norm(b, axis=1)).mean()
    return float(np.linalg.norm(a - b, axis=1).mean() / scale)


PPO_MEASURES: dict[str, Measure] = {
    "policy KL (symmetrised)": lambda a, b: gaussian_kl(a["mean"], a["std"], b["mean"], b["std"]),
    "value: mean abs difference": lambda a, b: mean_abs(a["value"], b["value"]),
}
DBC_MEASURES: dict[str, Measure] = {
    "critic: mean abs Q difference": lambda a, b: 0.5 * (mean_abs(a["q1"], b["q1"]) + mean_abs(a["q2"], b["q2"])),
    "actor: mean abs difference of the mean action": lambda a, b: mean_abs(a["action"], b["action"]),
    "encoder: relative L2 of the latent": lambda a, b: relative_l2(a["latent"], b["latent"]),
}


# ------------------------------------------------------------------------------ the rule (pure)
def passes(same: Sequence[float], cross: Sequence[float]) -> bool:
    """The rule: every same-order distance ``same`` ``(K,)`` is no larger than the smallest
    different-order fp32 distance in ``cross`` ``(K (K - 1) / 2,)``. NaN or empty input fails."""
    same_a, cross_a = np.asarray(same, dtype=np.float64), np.asarray(cross, dtype=np.float64)
    if same_a.size == 0 or cross_a.size == 0 or not (np.all(np.isfinite(same_a)) and np.all(np.isfinite(cross_a))):
        return False
    return bool(same_a.max() <= cross_a.min())


def compare(runs: dict[str, Any], measures: dict[str, Measure]) -> dict[str, dict[str, Any]]:
    """Per measure: same-order, different-order and update-size distances, and the rule's verdict.
    ``runs`` holds the outputs of ``initial`` (and ``initial_bf16``: the same weights run in bf16),
    ``fp32`` and ``bf16`` (lists over the K orders) and ``fp32_repeat`` (order 0 again)."""
    out = {}
    for name, d in measures.items():
        same = [d(a, b) for a, b in zip(runs["fp32"], runs["bf16"])]
        cross = [d(a, b) for a, b in itertools.combinations(runs["fp32"], 2)]
        out[name] = {"same_order": same, "fp32_orders": cross, "passes": passes(same, cross),
                     "update": [d(runs["initial"], a) for a in runs["fp32"]],
                     "repeat": d(runs["fp32"][0], runs["fp32_repeat"]),
                     "forward": d(runs["initial"], runs["initial_bf16"])}
    return out


# ------------------------------------------------------------------------------ report
def machine() -> dict[str, str]:
    """Host, CPU model and bf16 support, cores, load average and torch version."""
    flags, model = set(), platform.processor() or platform.machine()
    if Path("/proc/cpuinfo").exists():
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "flags":
                flags = set(value.split())
            elif key.strip() == "model name":
                model = value.strip()
    units = sorted(f for f in flags if f in {"avx512_bf16", "amx_bf16", "amx_tile", "avx512f"})
    return {"host": platform.node(), "cpu": model, "cores": str(os.cpu_count()),
            "bf16": ("native: " + ", ".join(units)) if "avx512_bf16" in flags or "amx_bf16" in flags
            else ("none in the CPU flags (no avx512_bf16 / amx_bf16; torch dispatches "
                  f"{torch.backends.cpu.get_cpu_capability()}): bf16 is emulated"),
            "load": ", ".join(f"{x:.2f}" for x in os.getloadavg()), "torch": torch.__version__,
            "threads": str(torch.get_num_threads())}


def _range(values: Sequence[float]) -> str:
    return f"{np.median(values):.3g} [{min(values):.3g}, {max(values):.3g}]"


def margin(same: Sequence[float], cross: Sequence[float]) -> float:
    """``max(same) / min(cross)``: the rule passes iff this is <= 1 (inf when ``cross`` has a 0)."""
    return float(max(same) / min(cross)) if min(cross) > 0 else float("inf")


def learner_table(title: str, learner: dict[str, Any]) -> list[str]:
    """One learner's section: sizes, CPU time, the table, the verdict."""
    result, cpu = learner["result"], learner["cpu_seconds"]
    verdict = "PASSES" if all(r["passes"] for r in result.values()) else "FAILS"
    fp32, bf16 = float(np.median(cpu["fp32"])), float(np.median(cpu["bf16"]))
    lines = [f"## {title}: bf16 {verdict}", "", learner["sizes_line"],
             f"CPU s per run of the update(s), median of {len(cpu['fp32'])}: fp32 {fp32:.1f}, bf16 {bf16:.1f} "
             f"({bf16 / fp32:.1f}x).", "",
             "| measure | same order: d(fp32_k, bf16_k), median [min, max] | different orders: d(fp32_i, fp32_j), "
             "median [min, max] | update size: d(initial, fp32_k), median | "
             "bf16 forward only: d(initial, initial in bf16) "
             "| fp32 repeat: d(fp32_0, fp32_0) | max same / min different | rule |",
             "|---|---|---|---|---|---|---|---|"]
    for name, r in result.items():
        lines.append(f"| {name} | {_range(r['same_order'])} | {_range(r['fp32_orders'])} | "
                     f"{np.median(r['update']):.3g} | {r['forward']:.3g} | {r['repeat']:.3g} | "
                     f"{margin(r['same_order'], r['fp32_orders']):.2f} | {'pass' if r['passes'] else 'FAIL'} |")
    return lines


def markdown(report: dict[str, Any]) -> str:
    """The report: command, machine and load, the rule, then one table per learner."""
    m, k = report["machine"], report["orders"]
    lines = ["# bf16 vs fp32: a null comparison of updates", "", f"Command: `{report['command']}`  ",
             f"Machine: {m['host']}: {m['cpu']}, {m['cores']} cores, torch {m['torch']}, {m['threads']} torch "
             f"thread(s); load average {report['load_before']} before, {m['load']} after; {report['seconds']:.0f} s.  ",
             f"bf16 on this CPU: {m['bf16']}.", "", *report["notes"], "",
             f"**Rule.** K = {k} minibatch orders. For each measure, bf16 passes iff max_k d(fp32_k, bf16_k) "
             f"<= min_(i<j) d(fp32_i, fp32_j): no bf16 network is further from the fp32 network of the same "
             f"order than any two fp32 networks of different orders are from each other (the noise the "
             f"algorithm already lives with). A learner passes iff all its measures pass. Networks are run in "
             f"their own precision on held-out observations. \"Update size\" is how far the fp32 update "
             f"moved the network; \"bf16 forward only\" runs the initial weights in bf16 (rounding without "
             f"training); \"fp32 repeat\" reruns order 0 (0 means the comparison is deterministic).", ""]
    for key, title in (("ppo", "PPO CNN (`carracing_ppo`)"), ("dbc", "DBC (`cheetah_dbc`)")):
        if key in report:
            lines += [*learner_table(title, report[key]), ""]
    return "\n".join(lines)


def notes(full_size: bool, native_bf16: bool) -> list[str]:
    """What the report answers at the sizes it ran at, and what it does not (``native_bf16``: the
    CPU has bf16 units, so the full size is affordable here)."""
    out = ["This compares numerics only. It says nothing about speed: bf16 is faster only on hardware "
           "with bf16 units (avx512_bf16 / AMX CPUs, CUDA GPUs)."]
    if not full_size:
        why = ("" if native_bf16 else " This CPU has no bf16 units: bf16 is emulated and runs many times slower "
               "than fp32 (CPU s per update below; `bench/cnn_speed.py` times the trunk alone), so the full "
               "size would take hours here.")
        out.append("The sizes are smaller than the issue's (PPO: a 16 x 1000 rollout, 10 epochs of minibatch "
                   f"1000; DBC: the 1000 random transitions and 1000 updates of the runner's first learning "
                   f"step).{why} The numerics question is answered at these sizes. Run the command with no size "
                   "options for the full-size comparison.")
    return out


def _sizes_line(key: str, sizes: dict[str, int]) -> str:
    if key == "ppo":
        return (f"Sizes: a rollout of {sizes['envs']} envs x {sizes['steps']} steps of the fixed initial policy "
                f"(envpool CarRacing), one PPO update of {sizes['epochs']} epoch(s) over minibatches of "
                f"{sizes['batch']} (SB3's `PPO.train`), {sizes['heldout']} held-out frames from other tracks.")
    return (f"Sizes: a replay of {sizes['transitions']} uniform-random transitions, {sizes['updates']} DBC updates "
            f"on minibatches of {sizes['batch']} (`DBCAgent.update`), {sizes['heldout']} held-out observations "
            f"of another episode.")


def run(sizes: Sizes, learners: Sequence[str], log: Callable[[str], None] = print) -> dict[str, Any]:
    """Every learner's runs and comparisons (the report without command and notes)."""
    from plls_bench.validation.precision_runs import dbc_runs, ppo_runs

    report: dict[str, Any] = {"orders": sizes.orders, "load_before": ", ".join(f"{x:.2f}" for x in os.getloadavg())}
    start = time.perf_counter()
    for key, runs, measures in (("ppo", ppo_runs, PPO_MEASURES), ("dbc", dbc_runs, DBC_MEASURES)):
        if key in learners:
            outputs = runs(sizes, log)
            report[key] = {"sizes": outputs["sizes"], "sizes_line": _sizes_line(key, outputs["sizes"]),
                           "cpu_seconds": outputs["cpu_seconds"], "result": compare(outputs, measures)}
    report["seconds"] = time.perf_counter() - start
    report["machine"] = machine()
    return report


def parse(argv: list[str] | None) -> tuple[argparse.Namespace, Sizes]:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--orders", type=int, default=3, help="minibatch orders K (>= 2)")
    for name, help_ in (("ppo-envs", "rollout envs (preset: 16)"), ("ppo-steps", "rollout steps per env (1000)"),
                        ("ppo-epochs", "PPO epochs (10)"), ("ppo-batch", "PPO minibatch size (1000)"),
                        ("dbc-transitions", "random transitions in the replay (init_steps, 1000)"),
                        ("dbc-updates", "DBC updates (init_steps, 1000)"), ("dbc-batch", "DBC minibatch size (128)")):
        parser.add_argument(f"--{name}", type=int, default=None, help=help_)
    parser.add_argument("--heldout", type=int, default=256, help="held-out observations per learner")
    parser.add_argument("--learners", nargs="+", choices=("ppo", "dbc"), default=["ppo", "dbc"])
    parser.add_argument("--threads", type=int, default=1, help="torch threads (1 on a busy CPU)")
    parser.add_argument("--out", type=Path, default=Path("results/analysis/precision_validation.md"))
    args = parser.parse_args(argv)
    if args.orders < 2:
        parser.error(f"--orders must be >= 2 (pairs of fp32 orders are the null), got {args.orders}")
    for name in ("ppo_envs", "ppo_steps", "ppo_epochs", "ppo_batch", "dbc_transitions", "dbc_updates",
                 "dbc_batch", "heldout", "threads"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    if args.out.suffix != ".md":
        parser.error(f"--out must name a .md file, got {args.out}")
    sizes = Sizes(args.orders, args.ppo_envs, args.ppo_steps, args.ppo_epochs, args.ppo_batch,
                  args.dbc_transitions, args.dbc_updates, args.dbc_batch, args.heldout)
    return args, sizes


def main(argv: list[str] | None = None) -> int:
    args, sizes = parse(argv)
    torch.set_num_threads(args.threads)
    report = run(sizes, args.learners, lambda msg: print(f"[precision {time.strftime('%H:%M:%S')}] {msg}", flush=True))
    report["command"] = "python -m plls_bench.validation.precision " + shlex.join(
        sys.argv[1:] if argv is None else argv)
    full = all(v is None for v in (args.ppo_envs, args.ppo_steps, args.ppo_epochs, args.ppo_batch,
                                   args.dbc_transitions, args.dbc_updates, args.dbc_batch))
    report["notes"] = notes(full, report["machine"]["bf16"].startswith("native"))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_json(args.out.with_suffix(".json"), report)
    atomic_write_bytes(args.out, markdown(report).encode())
    print(markdown(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
