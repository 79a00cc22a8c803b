"""What an untrained PPO policy actually sends to the env: raw actions vs actions decoded by V_a.

``python -m plls_bench.validation.action_spread [--budget quick] [--steps 999] [--trials 3]``

For each MountainCar method (plain PPO, PL-LS + PPO) and exploration setting (SB3's Gaussian,
gSDE) it builds the trial's untrained policy exactly as the PPO runner does (same seeds, same
env wrappers), rolls out ``--steps`` steps on ``n_envs`` training envs with sampled actions, and
records the env action of every step: for PL-LS the output of V_a's decoder
(``LatentAction.last_env_actions``), for plain PPO the sampled action clipped to [-1, 1] as SB3
clips it. The numbers say whether V_a's decoder squashes the exploration noise the policy emits
in its latent space. Writes ``results/analysis/action_spread.{json,md}``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from plls_bench.core.atomic_files import atomic_write_bytes, atomic_write_json
from plls_bench.core.seeding import derive_seeds
from plls_bench.rundirs.composition import compose

METHODS = {"PPO": "mountaincar_ppo", "PL-LS + PPO": "mountaincar_plls_ppo"}
EXPLORATION = ("gaussian", "gsde")


def env_actions(experiment: str, exploration: str, budget: str, seed: int, steps: int) -> np.ndarray:
    """``(steps, n_envs)`` env actions of the untrained policy of trial ``seed``, sampled."""
    from plls_bench.repr.store import ensure_representations
    from plls_bench.train.normalize import wrap_training
    from plls_bench.train.ppo_model import build_vec_env, new_model

    cfg = compose([f"+experiment={experiment}", f"budget={budget}", f"algo/exploration={exploration}",
                   f"seed={seed}", "progress=false", "device=cpu"])
    ppo = cfg.algo.ppo
    assert ppo is not None
    reprs = ensure_representations(cfg)  # as the PPO runner's setup: V_a built if missing
    venv = wrap_training(build_vec_env(cfg, ppo.n_envs, derive_seeds(seed, cfg.data_seed).train, reprs), ppo)
    model = new_model(cfg, venv)
    model.set_random_seed(derive_seeds(seed, cfg.data_seed).train)
    decoded = cfg.repr.action.kind == "vae"  # LatentAction keeps what it sent (reached through the wrappers)
    obs, out = venv.reset(), []
    if ppo.use_sde:
        model.policy.reset_noise(venv.num_envs)  # once per rollout, as SB3 PPO does
    for _ in range(steps):
        action, _ = model.predict(obs, deterministic=False)
        obs, _, _, _ = venv.step(action)
        sent = venv.last_env_actions if decoded else np.clip(action, -1.0, 1.0)
        out.append(np.asarray(sent, dtype=np.float64).reshape(venv.num_envs))
    venv.close()
    return np.stack(out)


def summary(actions: np.ndarray) -> dict[str, float]:
    """Spread of ``(T, n_envs)`` actions: std, mean |a|, share near the bounds, and the lag-1
    autocorrelation along time (how long a push in one direction lasts)."""
    centred = actions - actions.mean(axis=0)
    lag1 = float((centred[1:] * centred[:-1]).sum() / max((centred ** 2).sum(), 1e-12))
    return {"mean": float(actions.mean()), "std": float(actions.std()), "mean_abs": float(np.abs(actions).mean()),
            "share_abs_over_0.5": float((np.abs(actions) > 0.5).mean()),
            "share_at_bound": float((np.abs(actions) >= 0.999).mean()), "lag1_autocorrelation": lag1}


def measure(budget: str, steps: int, trials: int) -> list[dict[str, object]]:
    rows = []
    for exploration in EXPLORATION:
        for method, experiment in METHODS.items():
            per_trial = [summary(env_actions(experiment, exploration, budget, k, steps)) for k in range(trials)]
            rows.append({"exploration": exploration, "method": method, "experiment": experiment, "trials": trials,
                         **{key: float(np.mean([t[key] for t in per_trial])) for key in per_trial[0]}})
    return rows


def markdown(rows: list[dict[str, object]], steps: int) -> str:
    keys = ("std", "mean_abs", "share_abs_over_0.5", "share_at_bound", "lag1_autocorrelation")
    lines = [f"Untrained policy, sampled actions, {steps} steps x 32 envs, mean over {rows[0]['trials']} trials "
             "(`python -m plls_bench.validation.action_spread`)", "",
             "| exploration | method | " + " | ".join(keys) + " |", "|---|---|" + "---|" * len(keys)]
    lines += [f"| {r['exploration']} | {r['method']} | " + " | ".join(f"{float(r[k]):.3f}" for k in keys) + " |"
              for r in rows]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plls_bench.validation.action_spread",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--budget", default="quick", help="profile whose V_a the PL-LS policy decodes through")
    parser.add_argument("--steps", type=int, default=999, help="vector-env steps per trial (one episode: 999)")
    parser.add_argument("--trials", type=int, default=3, help="trial seeds 0..N-1")
    parser.add_argument("--out", default="results/analysis", help="folder for action_spread.{json,md}")
    args = parser.parse_args(argv)
    if args.steps < 2 or args.trials < 1:
        parser.error("--steps must be >= 2 and --trials >= 1")
    rows = measure(args.budget, args.steps, args.trials)
    text = markdown(rows, args.steps)
    atomic_write_json(Path(args.out) / "action_spread.json", {"budget": args.budget, "steps": args.steps, "rows": rows})
    atomic_write_bytes(Path(args.out) / "action_spread.md", text.encode())
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
