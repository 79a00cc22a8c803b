"""How fast DBC's latent loses its spread over a batch, in the first updates, per loss group.

    nice -n 5 .venv/bin/python bench/dbc_latent_spread.py                      # cheetah_dbc, budget=quick
    nice -n 5 .venv/bin/python bench/dbc_latent_spread.py --variants "" "algo=dbc_readme" --updates 25

The pixel DBC runs on a GPU (``docs/gpu_runs.md``) stayed at returns of 0.1-0.5 while
``train/latent_batch_std`` read 0.0: every frame mapped to the same latent. This script measures
when that starts. Per variant (overrides after the preset's), the env and agent are built as the
``dbc`` runner builds them (``bench/dbc_throughput.py``), the replay is filled with ``--steps``
uniform-random agent steps (the runner's warm-up), and from the same initial weights the agent
takes ``--updates`` updates of one loss group on replay minibatches:

- ``all``: the runner's full update (critic, then bisimulation + transition + reward, actor and
  temperature on even steps, target networks);
- ``critic``: the critic's TD loss alone (it also trains the critic's encoder);
- ``representation``: the bisimulation, transition and reward losses alone.

Reported: the latent's std over one fixed held-out batch, averaged over its 50 dimensions
(``baselines.dbc.bisim.latent_batch_std``), after 0, 1, 2, 5, ... updates; and, before any update,
what the encoder's LayerNorm sees: the conv features' mean and batch std, and the Linear layer's
output mean and batch std, also after one update of the critic loss. A ReLU trunk's features are
all >= 0 and mostly their common mean, so a first Adam step (each weight moves by about ``lr`` in
its gradient's sign) can add a large output shared by every frame, which the LayerNorm then scales
the per-frame part down against.
"""
from __future__ import annotations

import argparse
import copy
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from baselines.dbc.agent import Batch, DBCAgent  # noqa: E402
from baselines.dbc.bisim import latent_batch_std  # noqa: E402
from bench.benchmarks_md import announce, finish_section  # noqa: E402
from bench.dbc_throughput import build_trainer  # noqa: E402

SECTION = "dbc_latent_spread"
LOSS_GROUPS = ("all", "critic", "representation")


def update(agent: DBCAgent, group: str, batch: Batch, step: int) -> None:
    """One update of ``group``'s losses (``step`` keys the actor and target schedules)."""
    if group == "all":
        agent.update(batch, step)
    elif group == "critic":
        agent.update_critic(batch)
    elif group == "representation":
        agent.update_representation(batch)
    else:
        raise ValueError(f"loss group must be one of {LOSS_GROUPS}, got {group!r}")


@torch.no_grad()
def encoder_at_init(agent: DBCAgent, obs: torch.Tensor) -> dict[str, float]:
    """Means and batch stds of the conv features ``(B, F)`` and the Linear output ``(B, Z)``."""
    encoder = agent.critic.encoder
    features = encoder.features(obs)
    linear = encoder.fc(features)
    return {"feature_mean": float(features.mean()), "feature_batch_std": float(features.std(0).mean()),
            "linear_abs_mean": float(linear.mean(0).abs().mean()), "linear_batch_std": float(linear.std(0).mean())}


def spread_curve(agent: DBCAgent, group: str, sample: Callable[[], Batch], heldout: torch.Tensor,
                 at: list[int]) -> list[float]:
    """The latent's batch std on ``heldout`` after each count of updates in ``at`` (ascending)."""
    curve, done = [], 0
    for target in at:
        while done < target:
            done += 1
            update(agent, group, sample(), done)
        with torch.no_grad():
            curve.append(latent_batch_std(agent.critic.encoder(heldout)))
    return curve


def measure(preset: str, budget: str, variant: list[str], steps: int, at: list[int], groups: list[str],
            runs_dir: str) -> tuple[dict[str, float], dict[str, list[float]]]:
    """Encoder statistics at init and one spread curve per loss group, all from the same weights."""
    torch.manual_seed(0)
    trainer = build_trainer(preset, budget, runs_dir, variant)
    dbc = trainer.cfg.algo.dbc
    try:
        obs = trainer.train_env.reset()
        trainer.replay.start_episode(obs[0])
        for i in range(steps):  # steps below init_steps act uniformly at random, as the runner's warm-up
            obs, _, _ = trainer.step(obs, i, updates=False)
        rng = np.random.default_rng(1)
        sample = lambda: trainer.replay.sample(dbc.batch_size, rng, trainer.device)  # noqa: E731
        heldout = sample().obs
        start = copy.deepcopy(trainer.agent.state_dict())
        init = encoder_at_init(trainer.agent, heldout)
        update(trainer.agent, "critic", sample(), 1)
        init.update({f"{k}_after_1": v for k, v in encoder_at_init(trainer.agent, heldout).items()})
        weights = trainer.agent.critic.encoder.fc.weight.detach()
        init["linear_weight_step"] = float((weights - start["modules"]["critic"]["encoder.fc.weight"]).abs().max())
        curves = {}
        for group in groups:
            trainer.agent.load_state_dict(copy.deepcopy(start))
            torch.manual_seed(0)
            curves[group] = spread_curve(trainer.agent, group, sample, heldout, at)
            print(f"{preset} {' '.join(variant) or '(preset)'} {group}: {curves[group]}", flush=True)
    finally:
        trainer.train_env.close()
        trainer.eval_env.close()
    return init, curves


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--preset", default="cheetah_dbc")
    parser.add_argument("--budget", default="quick", help="budget whose DBC settings are used")
    parser.add_argument("--variants", nargs="+", default=[""],
                        help='override sets, each one string of space-separated overrides ("" = the preset)')
    parser.add_argument("--groups", nargs="+", default=list(LOSS_GROUPS), choices=LOSS_GROUPS)
    parser.add_argument("--steps", type=int, default=1000, help="random agent steps that fill the replay")
    parser.add_argument("--updates", type=int, default=25, help="updates per loss group")
    parser.add_argument("--runs", default="/tmp/plls_bench_dbc_bench", help="runs_dir (V_a artifacts)")
    parser.add_argument("--no-write", action="store_true", help="print only, leave docs/benchmarks.md alone")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    command = announce("dbc_latent_spread.py", argv)
    at = [n for n in (0, 1, 2, 5, 10, 25, 50, 100, 250, 1000) if n < args.updates] + [args.updates]
    rows = []
    for variant in args.variants:
        overrides = variant.split()
        init, curves = measure(args.preset, args.budget, overrides, args.steps, at, args.groups, args.runs)
        name = f"`{variant}`" if variant else "(preset)"
        rows += [f"| {name} | {group} | " + " | ".join(f"{v:.2g}" for v in curve) + " |"
                 for group, curve in curves.items()]
        rows.append(f"| {name} | encoder at init | conv features: mean {init['feature_mean']:.3g}, batch std "
                    f"{init['feature_batch_std']:.3g}; Linear output: mean magnitude {init['linear_abs_mean']:.3g}, "
                    f"batch std {init['linear_batch_std']:.3g} |" + " |" * (len(at) - 1))
        rows.append(f"| {name} | encoder after 1 critic update | Linear output: mean magnitude "
                    f"{init['linear_abs_mean_after_1']:.3g}, batch std {init['linear_batch_std_after_1']:.3g}; "
                    f"largest Linear weight change {init['linear_weight_step']:.2g} |" + " |" * (len(at) - 1))
    finish_section(
        SECTION, f"DBC latent spread over the first updates (`bench/dbc_latent_spread.py`, `{args.preset}`, "
        f"budget={args.budget})", command,
        f"Replay: {args.steps} uniform-random agent steps. Each loss group starts from the same initial "
        "weights. Cells: the LayerNorm'd latent's std over one fixed held-out batch, averaged over its "
        "dimensions, after that many updates (0 = initial weights); 0 means every frame maps to one latent.",
        ["variant", "losses", *[f"after {n}" for n in at]], rows, write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
