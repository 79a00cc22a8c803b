"""Where a trained PPO policy's mean action sits against its env's action bounds, and how far
acting on the mean is from what its sampled actions send on average.

``python -m plls_bench.validation.mean_action RUN_DIR [RUN_DIR ...] [--steps 400] [--out PREFIX]``

Each RUN_DIR is a run or a record (``results/records/<experiment>/<variant>/seed=<k>``). Its last
checkpointed policy acts on its mean, as in evaluation, on one env seeded as the trial's first
test episode, for ``--steps`` steps; each step records the Gaussian's mean and std per
action dimension. SB3 clips a sampled action to the bounds, so a sampling policy sends
E[clip(mean + std * noise)] on average, and a deterministic one clip(mean): the table gives both
per dimension, with the share of steps whose mean lies outside the bounds. Writes
``PREFIX.json`` and ``PREFIX.md`` (default ``results/analysis/mean_action``).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.stats import norm

from plls_bench.core.atomic_files import atomic_write_bytes, atomic_write_json
from plls_bench.core.seeding import derive_seeds

DEFAULT_OUT = Path("results/analysis/mean_action")


def clipped_gaussian_mean(mean: np.ndarray, std: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """E[clip(X, low, high)] for X ~ N(mean, std), elementwise; all arrays broadcast to ``(T, D)``."""
    alpha, beta = (low - mean) / std, (high - mean) / std
    inside = mean * (norm.cdf(beta) - norm.cdf(alpha)) + std * (norm.pdf(alpha) - norm.pdf(beta))
    return low * norm.cdf(alpha) + high * norm.sf(beta) + inside


def policy_trace(run_dir: Path, steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(means (T, D), stds (T, D), low (D,), high (D,))`` of the run's policy acting on its mean."""
    import torch

    from plls_bench.train.ppo_model import build_vec_env, load_trained

    trained = load_trained(run_dir, device="cpu")
    space = trained.model.action_space
    low, high = np.asarray(space.low, dtype=np.float64), np.asarray(space.high, dtype=np.float64)
    if not (np.isfinite(low).all() and np.isfinite(high).all()):
        raise ValueError(f"{run_dir}: the policy acts in an unbounded space (V_a's latent space); "
                         "nothing is clipped there")
    seed = derive_seeds(trained.cfg.seed, trained.cfg.data_seed).eval  # the first test episode's, as evaluate seeds it
    venv = build_vec_env(trained.cfg, 1, seed, trained.reprs)
    venv.seed(seed)
    obs, means, stds = venv.reset(), [], []
    policy = trained.model.policy
    for _ in range(steps):
        with torch.no_grad():
            gaussian = policy.get_distribution(policy.obs_to_tensor(trained.normalize_obs(obs))[0]).distribution
        means.append(gaussian.mean.cpu().numpy()[0])
        stds.append(gaussian.stddev.cpu().numpy()[0])
        obs, _, _, _ = venv.step(trained.act(obs))
    venv.close()
    return np.array(means, dtype=np.float64), np.array(stds, dtype=np.float64), low, high


def summary(means: np.ndarray, stds: np.ndarray, low: np.ndarray, high: np.ndarray) -> list[dict[str, float]]:
    """Per action dimension, over the ``(T, D)`` trace: the policy's mean and std, the shares of
    steps with the mean below / above the bounds, and the deterministic vs sampled env action."""
    sent = np.clip(means, low, high)
    sampled = clipped_gaussian_mean(means, stds, low, high)
    return [{"low": float(low[d]), "high": float(high[d]), "mean": float(means[:, d].mean()),
             "std": float(stds[:, d].mean()), "share_below": float((means[:, d] < low[d]).mean()),
             "share_above": float((means[:, d] > high[d]).mean()),
             "deterministic_action": float(sent[:, d].mean()), "sampled_action": float(sampled[:, d].mean()),
             "gap": float(np.abs(sent[:, d] - sampled[:, d]).mean())} for d in range(means.shape[1])]


def markdown(rows: dict[str, list[dict[str, float]]], steps: int) -> str:
    lines = ["# Mean action against the action bounds", "",
             f"`python -m plls_bench.validation.mean_action` ({steps} steps per run, acting on the mean). "
             "`deterministic` is the mean env action clip(mean), `sampled` the mean of "
             "E[clip(mean + std * noise)], `gap` the mean |difference| per step.", "",
             "| run | dim | bounds | mean | std | below | above | deterministic | sampled | gap |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for run, dims in rows.items():
        for d, r in enumerate(dims):
            lines.append(f"| {run} | {d} | [{r['low']:g}, {r['high']:g}] | {r['mean']:.3f} | {r['std']:.3f} | "
                         f"{r['share_below']:.2f} | {r['share_above']:.2f} | {r['deterministic_action']:.3f} | "
                         f"{r['sampled_action']:.3f} | {r['gap']:.3f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plls_bench.validation.mean_action",
                                     description=(__doc__ or "").split("\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="run dirs or records of PPO trials")
    parser.add_argument("--steps", type=int, default=400, help="steps of one test episode per run (default 400)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output prefix (default {DEFAULT_OUT})")
    args = parser.parse_intermixed_args(argv)  # run dirs before or after the options
    missing = [str(p) for p in args.runs if not (p / "config.json").is_file()]
    if missing or args.steps < 1:
        parser.error(f"runs: no config.json in {', '.join(missing)}" if missing else "--steps must be >= 1")
    rows = {}
    for run_dir in args.runs:
        print(f"[mean_action] {run_dir}: {args.steps} steps", file=sys.stderr)
        rows[str(run_dir)] = summary(*policy_trace(run_dir, args.steps))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_json(Path(f"{args.out}.json"), {"steps": args.steps, "runs": rows})
    atomic_write_bytes(Path(f"{args.out}.md"), markdown(rows, args.steps).encode())
    print(f"[mean_action] wrote {args.out}.json and {args.out}.md", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
