"""Synthetic run directories for testing the results collector before the experiments exist.

Every file follows the "What each runner writes" table (docs/architecture.md) and is written through
:class:`plls_bench.rundirs.run_dir.Run`; configs are composed from the shipped yaml (the group choices each
registry preset stands for, at the given budget), never written by hand.
"""
from __future__ import annotations

import dataclasses
import io
from collections.abc import Sequence
from functools import cache
from pathlib import Path

import numpy as np

from plls_bench.config import Config
from plls_bench.core.atomic_files import atomic_write_json, read_json
from plls_bench.pipeline.sweeps import load_sweep, sweep_names
from plls_bench.report.registry import ENTRIES
from plls_bench.rundirs.composition import compose
from plls_bench.rundirs.run_dir import ARCHITECTURE_FILE, PARAMS_FILE, STATUS_DONE, Run, config_hash, run_dir_path

# The group choices of each registry preset; shipped presets where they exist (PPO: issue 4, the
# MountainCar studies: issue 6), the rest until their issues ship them.
DBC = ["env=cheetah", "algo=dbc", "runner=dbc"]
PRESETS: dict[str, list[str]] = {
    **{name: [f"+experiment={name}"] for name in ("mountaincar_ppo", "mountaincar_plls_ppo", "carracing_ppo",
                                                   "carracing_plls_ppo", "carracing_ppo_vs", "carracing_ppo_va",
                                                   "mountaincar_multistep", "mountaincar_onestep",
                                                   "mountaincar_generalisation", "mountaincar_ppo_gsde",
                                                   "mountaincar_plls_ppo_gsde", "mountaincar_ppo_zoo",
                                                   "cheetah_sac_state", "cheetah_sac_pixel", "carracing_ppo_gsde",
                                                   "carracing_plls_ppo_gsde")},
    "cheetah_dbc": DBC,
    "cheetah_plls_dbc": [*DBC, "repr/action=vae"],
    "mountaincar_va": ["env=mountaincar", "runner=repr", "repr/action=vae"],
    "carracing_vs": ["env=carracing", "runner=repr", "repr/state=vae"],
    "carracing_va": ["env=carracing", "runner=repr", "repr/action=vae"],
    "carracing_data": ["+experiment=carracing_data"],
}


@cache
def _compose(experiment: str, budget: str, runs_dir: str, *overrides: str) -> Config:
    cfg = compose([*PRESETS[experiment], f"budget={budget}", f"runs_dir={runs_dir}", "progress=false", *overrides])
    return dataclasses.replace(cfg, experiment=experiment)  # `experiment=` on a command line picks a preset


def make_run(runs_dir: Path, experiment: str, seed: int, budget: str = "quick",
             *overrides: str, variant: str = "default") -> tuple[Run, Config]:
    """A prepared run dir (config.json, provenance.json, status running) for ``experiment``."""
    cfg = dataclasses.replace(_compose(experiment, budget, str(runs_dir), *overrides), seed=seed)
    run = Run(run_dir_path(runs_dir, experiment, variant, seed))
    run.prepare(cfg, config_hash(cfg))
    run.write_status("running", config_hash=config_hash(cfg))
    return run, cfg


def finish(run: Run, cfg: Config, state: str = STATUS_DONE) -> None:
    error = {"error": "RuntimeError: boom"} if state == "failed" else {}
    run.write_status(state, config_hash=config_hash(cfg), **error)


def set_starts(run_dir: Path, *starts: tuple[str, str]) -> None:
    """Rewrite ``run_dir``'s provenance.json as a trial launched once per ``(device, git sha)`` in
    ``starts``, laid out as the run dir writes it: every start in "starts", the first on top."""
    path = run_dir / "provenance.json"
    first = read_json(path)["starts"][0]
    written = [{**first, "device_resolved": device, "git_sha": sha} for device, sha in starts]
    atomic_write_json(path, {**written[0], "starts": written})


def write_npz(run: Run, relpath: str, **arrays: np.ndarray) -> None:
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    run.write_bytes(relpath, buffer.getvalue())


# --------------------------------------------------------------------------- metric files
def write_eval(run: Run, cfg: Config, iterations: Sequence[int], returns: Sequence[Sequence[float]],
               stochastic_offset: float = -1.0) -> None:
    """``metrics/eval.jsonl``: one row per evaluation with its episode returns (and train rows);
    PPO's sampled-action returns are the deterministic ones plus ``stochastic_offset``."""
    ppo = cfg.algo.name == "ppo"
    per_iteration = cfg.algo.ppo.n_envs * cfg.algo.ppo.n_steps if ppo else cfg.env.action_repeat
    for iteration, episodes in zip(iterations, returns):
        env_steps = iteration * per_iteration
        row = {"env_steps": env_steps, "iteration": iteration, "agent_steps": env_steps // cfg.env.action_repeat,
               "wall_s": 1.5 * iteration, "episode_returns": list(map(float, episodes)),
               "return_mean": float(np.mean(episodes)), "episode_lengths": [100] * len(episodes)}
        if ppo:
            row["episode_returns_stochastic"] = [float(r) + stochastic_offset for r in episodes]
        run.log("eval", row)
        run.log("train", {"env_steps": env_steps, "iteration": iteration, "wall_s": 1.5 * iteration,
                          "loss/policy": 0.1, "loss/value": 1.0, "perf/sps": 1000.0})


def write_repr(run: Run, model: str, epochs: int, test_mse: float, artifact: str, scale: float = 1.0) -> None:
    """``repr_train.jsonl`` rows for ``model`` (losses falling with the epoch) and ``repr_test.json``."""
    for epoch in range(1, epochs + 1):
        mse = scale * (0.3 / epoch + test_mse)
        run.log("repr_train", {"model": model, "epoch": epoch, "train_loss": mse + 0.01, "train_recon_mse": mse,
                               "train_kl": 0.01, "val_loss": 1.1 * mse + 0.01, "val_recon_mse": 1.1 * mse,
                               "val_kl": 0.01})
    previous = read_json(run.path / "metrics" / "repr_test.json") or {}
    run.write_json("metrics/repr_test.json", {**previous, model: {"test_mse": test_mse, "n_test": 100,
                                                                  "artifact": artifact}})


def write_params(run: Run, total: int, trainable: int) -> None:
    run.write_json(PARAMS_FILE, {"total": total, "trainable": trainable, "modules": {
        "policy": {"total": trainable, "trainable": trainable},
        "frozen": {"total": total - trainable, "trainable": 0}}})


def write_architecture(run: Run, trainable: bool) -> None:
    def conv(name: str, shape: list[int], params: int) -> dict:
        return {"name": name, "type": "Conv2d", "output_shape": shape, "params": params, "trainable": trainable}

    relu = {"name": "relu", "type": "ReLU", "output_shape": [32, 47, 47], "params": 0, "trainable": trainable}
    run.write_json(ARCHITECTURE_FILE, {
        "encoder": [conv("conv1", [32, 47, 47], 1568), relu, conv("conv2", [64, 22, 22], 32832)],
        "policy": [{"name": "fc", "type": "Linear", "output_shape": [32], "params": 1056, "trainable": True},
                   {"name": "tanh", "type": "Tanh", "output_shape": [32], "params": 0, "trainable": True}]})


def write_study(run: Run, study: str, rng: np.random.Generator) -> None:
    """``studies/<study>.npz`` with the arrays issue 6 defines, and ``metrics/study.json``."""
    if study == "generalisation":
        actions = np.concatenate([-rng.uniform(0, 1, 5), rng.uniform(0, 1, 5)])
        e = rng.normal(size=(10, 10, 3))
        arrays = dict(actions=actions, mu=e.mean(axis=1), std=e.std(axis=1), e=e,
                      decoded=actions[:, None] + 0.05 * rng.normal(size=(10, 10)),
                      next_states=rng.normal(size=(10, 10, 2)) * 0.01, s0=np.array([-0.5233, 0.0]))
    else:
        actions = rng.uniform(-1, 1, 1000) if study == "multistep" else np.concatenate(
            [-rng.uniform(0, 1, 500), rng.uniform(0, 1, 500)])
        e = np.stack([actions, actions ** 2, np.sin(3 * actions)], axis=1)
        arrays = dict(actions=actions, mu=e, e=e + 0.01 * rng.normal(size=e.shape), decoded=actions * 0.98)
        if study == "multistep":
            arrays.update(states_raw=np.cumsum(rng.normal(size=(1001, 2)), axis=0) * 0.01,
                          states_decoded=np.cumsum(rng.normal(size=(1001, 2)), axis=0) * 0.01)
        else:
            arrays.update(next_states_raw=np.stack([-0.5233 + 0.001 * actions, 0.001 * actions], axis=1),
                          next_states_decoded=np.stack([-0.5233 + 0.00098 * actions, 0.00098 * actions], axis=1),
                          s0=np.array([-0.5233, 0.0]))
    write_npz(run, f"studies/{study}.npz", **arrays)
    run.write_json("metrics/study.json", {"reconstruction_mse": 0.0004, "n_actions": len(actions)})


def write_filmstrip(run: Run, frames: int, interval: int, steps_to_goal: int | None,
                    hw: tuple[int, int] = (40, 60)) -> None:
    images = np.zeros((frames, *hw, 3), dtype=np.uint8)
    images[..., 1] = np.linspace(0, 255, frames, dtype=np.uint8)[:, None, None]
    write_npz(run, "filmstrip/frames.npz", frames=images)
    run.write_json("filmstrip/filmstrip.json", {"interval": interval, "episode_return": 93.5,
                                                "frame_steps": [i * interval for i in range(frames)],
                                                "steps_to_goal": steps_to_goal})


def write_samples(run: Run, rng: np.random.Generator) -> None:
    """Fig 14's frames (one on the road, one on the grass) and Fig 16's first 200 test actions."""
    frames = rng.integers(0, 255, size=(2, 3, 96, 96), dtype=np.uint8)
    write_npz(run, "samples/state_reconstructions.npz", originals=frames, reconstructions=frames // 2 + 60,
              labels=np.array(["road", "grass"]))
    actions = rng.uniform(0, 1, size=(200, 3))
    write_npz(run, "samples/action_reconstructions.npz", actions=actions, reconstructions=actions + 0.01)


# --------------------------------------------------------------------------- a whole suite
PLLS_FILMSTRIPS = {"mountaincar_plls_ppo": (18, 4, 70), "mountaincar_plls_ppo_gsde": (18, 4, 66),
                   "carracing_plls_ppo": (21, 48, None),
                   "cheetah_plls_dbc": (25, 40, None)}  # frames, interval, steps to goal


def fill(run: Run, cfg: Config, rng: np.random.Generator) -> None:
    """Every file the run's runner writes, with plausible values."""
    name = cfg.experiment
    if cfg.runner in ("ppo", "dbc"):
        iterations = list(range(0, 24, 2))
        top = 90.0 if "plls" in name else 60.0
        write_eval(run, cfg, iterations, [[top * (1 - np.exp(-i / 6)) + rng.normal(0, 5) for _ in range(3)]
                                          for i in iterations])
        write_params(run, 8802 if "plls" in name else 3_289_768, 4394 if "plls" in name else 1_644_878)
        write_architecture(run, trainable="plls" not in name)
        if name in PLLS_FILMSTRIPS and cfg.seed == 0:
            write_filmstrip(run, *PLLS_FILMSTRIPS[name])
        if cfg.runner == "ppo" and cfg.repr.action.kind == "vae":  # PPO runs record their V_a's test MSE
            run.write_json("metrics/repr_test.json", {"action": {
                "test_mse": 0.01, "test_mse_posterior_mean": 0.001, "n_test": 100,
                "artifact": f"va-{cfg.repr.action.latent_dim}-{cfg.seed}"}})
    elif cfg.runner == "collect":
        run.write_json("metrics/dataset.json", {"task": cfg.env.name, "transitions": 10_000, "episodes": 10,
                                                "episode_return_mean": -55.3, "episode_return_std": 18.0})
    elif cfg.runner == "repr":
        for model, kind in (("state", cfg.repr.state.kind), ("action", cfg.repr.action.kind)):
            if kind == "vae":  # one representation shared by all trials, as in the paper's offline phase
                write_repr(run, model, cfg.budget.repr_epochs, 0.012, artifact=f"{model}-shared")
        write_samples(run, rng)
        write_params(run, 4_000_000, 4_000_000)
        write_architecture(run, trainable=True)
    else:
        write_study(run, name.split("_", 1)[1], rng)


def build_all(runs_dir: Path, budget: str = "quick") -> list[Path]:
    """Complete runs (every seed of the budget) of every preset the registry reads."""
    rng = np.random.default_rng(0)
    paths = []
    for experiment in sorted({e for entry in ENTRIES for e in entry.experiments}):
        for seed in range(_compose(experiment, budget, str(runs_dir)).budget.trials):
            run, cfg = make_run(runs_dir, experiment, seed, budget)
            fill(run, cfg, rng)
            finish(run, cfg)
            paths.append(run.path)
    for sweep in map(load_sweep, sweep_names()):  # each declared sweep's other values, as override variants
        for value in sweep.others:
            override = sweep.override(value)
            for seed in range(_compose(sweep.preset, budget, str(runs_dir), override).budget.trials):
                run, cfg = make_run(runs_dir, sweep.preset, seed, budget, override, variant=override)
                fill(run, cfg, rng)
                finish(run, cfg)
                paths.append(run.path)
    return paths


# tests/test_report.py's hand-computed runs. Three trials per method: the fewest a comparison is
# judged from (report.matched.MIN_TRIALS). Each mean curve is that of the first two trials alone
# (PL-LS 0, 50, 90, 100, ...; PPO 5i + 10).
ITERATIONS = list(range(0, 24, 2))  # 12 evaluations, one every 2 PPO iterations (quick budget)
PLLS_RETURNS = {0: [0, 20, 80] + [100] * 9, 1: [0, 80, 100] + [100] * 9, 2: [0, 50, 90] + [100] * 9}
PPO_RETURNS = {0: [5 * i for i in range(12)], 1: [5 * i + 10 for i in range(12)], 2: [5 * i + 20 for i in range(12)]}


def build_hand_runs(runs_dir: Path, budget: str = "quick") -> None:
    """CarRacing PL-LS and PPO with known curves and counts, V_a with known MSEs, a filmstrip."""
    for experiment, curves, params in (("carracing_plls_ppo", PLLS_RETURNS, (8802, 4394)),
                                       ("carracing_ppo", PPO_RETURNS, (3_289_768, 1_644_878))):
        for seed, curve in curves.items():
            # the budget's own count at smoke (2) would leave no gap; set it to the trials written
            run, cfg = make_run(runs_dir, experiment, seed, budget, f"budget.trials={len(curves)}")
            write_eval(run, cfg, ITERATIONS, [[r - 1, r + 1] for r in curve])  # episode mean = r
            write_params(run, *params)
            finish(run, cfg)
    models = [(0.010, "a"), (0.014, "b"), (0.010, "a"), (0.018, "c")]  # 3 distinct models, a shared by 2 trials
    for seed, (mse, artifact) in enumerate(models):
        run, cfg = make_run(runs_dir, "mountaincar_va", seed, budget, f"budget.trials={len(models)}")
        write_repr(run, "action", 3, mse, artifact)
        finish(run, cfg)
    run, cfg = make_run(runs_dir, "mountaincar_plls_ppo", 0, budget)
    write_filmstrip(run, frames=18, interval=4, steps_to_goal=70)
    finish(run, cfg)
