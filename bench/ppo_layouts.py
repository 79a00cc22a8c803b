"""PPO training env steps/s per conv memory layout and precision, in one interleaved run.

    nice -n 10 .venv/bin/python bench/ppo_layouts.py --presets carracing_ppo --backend envpool \\
        --n-steps 64 --iterations 2 --layouts contiguous channels_last --precisions fp32

Each setting (layout x precision) gets the preset's real SB3 training loop, built exactly as the
``ppo`` runner builds it (``bench/ppo_throughput.py``'s ``build``). Every setting runs one
warm-up iteration, then the ``--iterations`` timed iterations go round-robin over the settings
(setting A, B, A, B, ...), so a drift in the machine's other load hits every setting alike: compare
ratios within one run only.

- ``channels_last`` is the suite's layout (``plls_bench/repr/pixel_trunk.py``: every conv trunk runs in its
  conv weights' layout). ``contiguous`` converts the built policy's weights (and V_s's frozen
  encoder in the latent wrapper, for PL-LS and V_s only) back with
  ``.to(memory_format=torch.contiguous_format)``, which reproduces the layout before that change;
  the uint8 rollout frames and everything else stay as they are, only the memory format changes.
- ``--precisions`` sets the top-level ``precision`` key (``bf16``: autocast around the trunks).
- ``--n-steps`` shortens the horizon (per env; the update keeps the preset's epochs and minibatch
  size), so an iteration of ``carracing_ppo`` takes about a minute instead of about 15.

Prints the command, the machine and load before and after, and rewrites this script's section of
``docs/benchmarks.md``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.benchmarks_md import announce, finish_section  # noqa: E402
from bench.ppo_throughput import Sample, build, iteration, summarize  # noqa: E402
from bench.representations import TINY_REPR, prepare_representations  # noqa: E402
from plls_bench.config import PRECISIONS  # noqa: E402
from plls_bench.config.tasks import ENV_BACKENDS  # noqa: E402
from plls_bench.repr.latent_wrappers import latent_modules  # noqa: E402
from plls_bench.repr.pixel_trunk import memory_format  # noqa: E402
from plls_bench.rundirs.composition import compose  # noqa: E402
from plls_bench.train.ppo import EpisodeStats  # noqa: E402

SECTION = "ppo_layouts"
NO_BF16 = ("bf16 not run here: a CPU without bf16 instructions (no avx512_bf16 / AMX) emulates it, "
           "7-17x slower than fp32 (results/analysis/precision_validation.md); `--precisions fp32 bf16` adds it.")
LAYOUTS = {"contiguous": torch.contiguous_format, "channels_last": torch.channels_last}


def run_settings(preset: str, args: argparse.Namespace) -> list[tuple[str, str, dict[str, float]]]:
    """(layout, precision, summary) per setting of ``preset``, timed round-robin."""
    base = [*TINY_REPR, *([f"algo.ppo.n_steps={args.n_steps}"] if args.n_steps else []),
            *([f"env.backend={args.backend}"] if args.backend else [])]
    settings, built = [(lay, prec) for prec in args.precisions for lay in args.layouts], []
    try:
        for layout, precision in settings:
            overrides = [*base, f"precision={precision}"]
            prepare_representations(compose([f"+experiment={preset}", f"budget={args.budget}",
                                             f"runs_dir={args.runs}", "progress=false", *overrides]))
            venv, model, steps = build(preset, args.budget, args.runs, overrides)
            # in place, so the optimizer keeps its parameters; V_s's frozen encoder (PL-LS, V_s only) too
            for module in (model.policy, *latent_modules(venv).values()):
                module.to(memory_format=LAYOUTS[layout])
                assert memory_format(module) == LAYOUTS[layout] or not _has_conv(module), layout
            built.append((venv, model, steps, EpisodeStats()))
            iteration(model, steps, built[-1][3])  # warm-up
        samples: list[list[Sample]] = [[] for _ in settings]
        for i in range(args.iterations):
            for k, (_, model, steps, stats) in enumerate(built):
                if i < _iterations(settings[k][1], args):
                    samples[k].append(iteration(model, steps, stats))
                    print(f"  {preset} {settings[k]} iteration {i + 1}: {samples[k][-1][1]:.1f} s", flush=True)
    finally:
        for venv, *_ in built:
            venv.close()
    return [(lay, prec, summarize(b[2], s)) for (lay, prec), b, s in zip(settings, built, samples)]


def _has_conv(module: torch.nn.Module) -> bool:
    return any(isinstance(m, torch.nn.Conv2d) for m in module.modules())


def _iterations(precision: str, args: argparse.Namespace) -> int:
    """Timed iterations of a setting: ``--bf16-iterations`` caps bf16's (emulated on CPUs without
    bf16 instructions, so 10-20x slower there)."""
    return min(args.iterations, args.bf16_iterations) if precision == "bf16" else args.iterations


def rows(preset: str, results: list[tuple[str, str, dict[str, float]]]) -> list[str]:
    """Table rows; the ratio is steps/s over the contiguous fp32 setting's (when measured)."""
    ref = next((m["sps"] for lay, prec, m in results if (lay, prec) == ("contiguous", "fp32")), None)
    return [f"| `{preset}` | {lay} | {prec} | {m['steps']} | {m['rollout_s']:.2f} | {m['update_s']:.2f} | "
            f"**{m['sps']:.1f}** | {m['cpu_s']:.2f} | {m['cpu_sps']:.1f} | "
            + (f"{m['sps'] / ref:.2f}x |" if ref else "n/a |") for lay, prec, m in results]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--presets", nargs="+", default=["carracing_ppo"])
    parser.add_argument("--budget", default="quick", help="budget whose PPO settings are used")
    parser.add_argument("--backend", default=None, choices=ENV_BACKENDS, help="env.backend (default: the profile's)")
    parser.add_argument("--layouts", nargs="+", default=list(LAYOUTS), choices=list(LAYOUTS))
    parser.add_argument("--precisions", nargs="+", default=["fp32"], choices=PRECISIONS)
    parser.add_argument("--iterations", type=int, default=2, help="timed PPO iterations per setting")
    parser.add_argument("--bf16-iterations", type=int, default=1, help="at most this many timed for bf16")
    parser.add_argument("--n-steps", type=int, default=64, help="horizon per env (0: the preset's)")
    parser.add_argument("--runs", default="/tmp/plls_bench_layouts", help="runs_dir (a tiny V_s / V_a is built)")
    parser.add_argument("--no-write", action="store_true", help="print only, leave docs/benchmarks.md alone")
    args = parser.parse_args(argv)
    if min(args.iterations, args.bf16_iterations) < 1 or args.n_steps < 0:
        parser.error("--iterations and --bf16-iterations must be >= 1, --n-steps >= 0")
    command = announce("ppo_layouts.py", argv)
    table = []
    for preset in args.presets:
        table += rows(preset, run_settings(preset, args))
        print("\n".join(table[-len(args.layouts) * len(args.precisions):]), flush=True)
    finish_section(
        SECTION, f"PPO env steps/s per conv layout and precision (`bench/ppo_layouts.py`, budget={args.budget})",
        command, f"Median of the timed iterations (`--iterations {args.iterations}`, bf16 at most "
        f"{args.bf16_iterations}) after one warm-up per setting, interleaved round-robin over the "
        "settings so load drifts hit all alike. "
        + (f"Horizon shortened to n_steps={args.n_steps} per env; " if args.n_steps else "Preset horizon; ")
        + "the update keeps the preset's epochs and minibatch size. `contiguous` converts the built "
        "policy and V_s's frozen encoder back to contiguous_format (the layout before every conv trunk "
        "ran channels_last); "
        "uint8 rollout frames stay. CPU s is the process's CPU time per iteration. Ratio: steps/s "
        "over contiguous fp32 in the same run.",
        ["preset", "layout", "precision", "env steps / iteration", "rollout s", "update s", "steps/s",
         "CPU s / iteration", "steps per CPU-s", "ratio"], table,
        notes=None if "bf16" in args.precisions else [NO_BF16], write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
