"""The DBC presets end to end at smoke budget, from pixels, through the CLI; SIGKILL and resume."""
from __future__ import annotations

import copy
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from plls_bench.core.atomic_files import read_json, read_jsonl
from plls_bench.rundirs.artifacts import load_npz
from plls_bench.rundirs.run_dir import ARCHITECTURE_FILE, PARAMS_FILE, Run
from plls_bench.train.dbc import DBCTrainer
from plls_bench.train.loop import Progress
from tests.conftest import REPO_ROOT, compose_preset

# smoke budget: 400 env steps (200 agent steps at cheetah_dbc's action repeat 2), evaluations every 200
EVAL_STEPS = [0, 200, 400]
TRAIN_KEYS = {"env_steps", "iteration", "agent_steps", "wall_s", "loss/critic", "loss/actor", "loss/alpha",
              "loss/encoder_bisim", "loss/transition", "loss/reward", "train/latent_batch_std", "perf/updates_per_s",
              "perf/env_steps_per_s"}


def cli(runs_dir: Path, *overrides: str, experiment: str = "cheetah_dbc") -> list[str]:
    return [sys.executable, "-m", "plls_bench", f"+experiment={experiment}", "budget=smoke",
            f"runs_dir={runs_dir}", "progress=false", "torch_threads=1", *overrides]


def wait_for_evaluations(run_dir: Path, process: subprocess.Popen, count: int, timeout: float = 600) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        progress = read_json(run_dir / "checkpoints" / "progress.json") or {}
        if progress.get("evaluations", 0) >= count:
            return
        assert process.poll() is None, "the run ended before it could be killed"
        time.sleep(0.2)
    raise AssertionError(f"no checkpoint after {count} evaluations within {timeout}s")


def action_repeat(run_dir: Path) -> int:
    """The action repeat the run was made with (its recorded config)."""
    return read_json(run_dir / "config.json")["config"]["env"]["action_repeat"]


def check_contract(run_dir: Path) -> list[dict]:
    assert read_json(run_dir / "status.json")["state"] == "done"
    evals = read_jsonl(run_dir / "metrics" / "eval.jsonl")
    assert [r["env_steps"] for r in evals] == EVAL_STEPS, "one row per evaluation, none lost or repeated"
    for row in evals:
        assert row["agent_steps"] == row["iteration"] == row["env_steps"] // action_repeat(run_dir)
        # smoke budget: budget.eval_max_steps = 50 cuts the 500-step test episode
        assert len(row["episode_returns"]) == len(row["episode_lengths"]) == 1
        assert row["episode_lengths"] == [50] and row["return_mean"] == row["episode_returns"][0]
    train = read_jsonl(run_dir / "metrics" / "train.jsonl")
    steps = [r["env_steps"] for r in train]
    assert steps == sorted(set(steps)) and steps[-1] == 400
    assert TRAIN_KEYS <= set(train[-1]), TRAIN_KEYS - set(train[-1])
    params = read_json(run_dir / PARAMS_FILE)
    assert params["total"] == sum(m["total"] for m in params["modules"].values())
    assert params["modules"]["critic_target"]["trainable"] == 0 and params["trainable"] < params["total"]
    convs = [layer for layer in read_json(run_dir / ARCHITECTURE_FILE)["encoder"]
             if layer["type"] == "Conv2d"]
    assert [c["output_shape"] for c in convs] == [[1, 32, 41, 41], [1, 32, 39, 39], [1, 32, 37, 37], [1, 32, 35, 35]]
    return evals


@pytest.mark.slow
def test_cheetah_dbc_from_pixels_survives_sigkill_and_resumes(runs_dir: Path) -> None:
    """Killed mid-training after its second checkpoint, the run resumes there: the evaluations
    already logged are kept as they were, none is repeated, the replay is restored."""
    run_dir = runs_dir / "cheetah_dbc" / "default" / "seed=0"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    process = subprocess.Popen(cli(runs_dir), cwd=REPO_ROOT, env=env, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    try:
        wait_for_evaluations(run_dir, process, 2)
        time.sleep(1.0)  # into the training steps after the checkpoint
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    before = read_jsonl(run_dir / "metrics" / "eval.jsonl")
    assert [r["env_steps"] for r in before][:2] == EVAL_STEPS[:2]
    assert read_json(run_dir / "status.json")["state"] == "running"

    done = subprocess.run(cli(runs_dir), cwd=REPO_ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    evals = check_contract(run_dir)
    assert evals[:2] == before[:2], "rows before the checkpoint are kept unchanged"
    assert len(read_json(run_dir / "provenance.json")["starts"]) == 2
    progress = read_json(run_dir / "checkpoints" / "progress.json")
    # at action repeat 2: 101 slots restored (100 transitions + reset frame), a fresh episode on resume (1),
    # 100 more; the replay holds the run's 200 transitions, one reset frame per episode begun, and one spare
    half = EVAL_STEPS[1] // action_repeat(run_dir)
    assert action_repeat(run_dir) == 2 and progress["replay_written"] == 2 * half + 2
    assert progress["agent_steps"] == 2 * half
    output = done.stdout + done.stderr  # memory use is reported at start
    assert f"replay: {2 * half + 2} slots" in output and "reference layout 190548 bytes/transition" in output


@pytest.mark.slow
def test_plls_dbc_acts_through_the_frozen_action_decoder(runs_dir: Path) -> None:
    """PL-LS + DBC: the same runner, acting in V_a's 12-D latent box; V_a is built on first use."""
    done = subprocess.run(cli(runs_dir, experiment="cheetah_plls_dbc"), cwd=REPO_ROOT, capture_output=True,
                          text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    run_dir = runs_dir / "cheetah_plls_dbc" / "default" / "seed=0"
    check_contract(run_dir)
    params = read_json(run_dir / PARAMS_FILE)
    assert params["modules"]["V_a.decoder"]["total"] > 0 and params["modules"]["V_a.decoder"]["trainable"] == 0
    architecture = read_json(run_dir / ARCHITECTURE_FILE)
    assert architecture["actor"][-1]["output_shape"] == [1, 24], "mean and log-std of e in R^12"
    assert architecture["V_a.decoder"][-1]["output_shape"] == [1, 6], "decoded to cheetah's 6-D action"
    chunks = sorted((run_dir / "checkpoints" / "replay").glob("chunk_*.npz"))
    actions = np.concatenate([load_npz(c)["actions"] for c in chunks])
    assert actions.shape[1] == 12 and np.abs(actions).max() <= 1.0, "stored: the agent's e / bound"


def test_dbc_settings_are_validated(runs_dir: Path) -> None:
    from plls_bench.config import ConfigError

    for override, key in (("algo.dbc.transition_model=ensemble", "algo.dbc.transition_model"),
                          ("algo.dbc.batch_size=0", "algo.dbc.batch_size"),
                          ("algo.dbc.critic_tau=1.5", "algo.dbc.critic_tau"),
                          ("algo.dbc.sigma_min=20", "algo.dbc.sigma_min")):
        with pytest.raises(ConfigError, match=key):
            compose_preset("cheetah_dbc", runs_dir, override)
    # Sec. 5.3 ran 5; Fig. 21's rows plan 6 (results/paper/claims.yaml), which both profiles run
    assert compose_preset("cheetah_dbc", runs_dir, "budget=paper").budget.trials == 6


@pytest.mark.slow
def test_the_burst_estimate_times_a_copy_and_leaves_the_run_as_it_was(runs_dir: Path) -> None:
    """Before the burst of ``init_steps`` updates the trainer times updates on a throw-away copy of
    its agent (loop.TimeLimit): the run's agent, optimisers, sampling generator and torch RNG come
    out bit for bit as they went in, so a time limit never changes what a run learns."""
    cfg = compose_preset("cheetah_dbc", runs_dir, "algo.dbc.init_steps=30", "torch_threads=1")
    trainer = DBCTrainer(cfg, Run(runs_dir / "burst"))
    trainer.setup()
    try:
        trainer.start(Progress(), resumed=False)
        at = Progress()
        while at.agent_steps < 30:  # random acting, no update yet
            at, _ = trainer.train_iteration(at)
        before = copy.deepcopy(trainer.agent.state_dict()), trainer.rng.bit_generator.state, torch.get_rng_state()
        seconds = trainer.interval_ahead_s(at)
        after = trainer.agent.state_dict(), trainer.rng.bit_generator.state, torch.get_rng_state()
        assert seconds > 0, "init_steps=30 comes before this episode's end"
        assert trainer.interval_ahead_s(replace(at, agent_steps=31)) == 0.0, "the burst is behind it"
        assert trainer.interval_ahead_s(replace(at, agent_steps=30 - trainer.episode_steps)) == 0.0, "an episode ahead"
    finally:
        trainer.close()
    assert before[1] == after[1] and torch.equal(before[2], after[2])
    flat_before, flat_after = _tensors(before[0]), _tensors(after[0])
    assert flat_before.keys() == flat_after.keys() and len(flat_before) > 50
    assert all(torch.equal(flat_before[k], flat_after[k]) for k in flat_before)


def _tensors(state: Any, prefix: str = "") -> dict[str, torch.Tensor]:
    """Every tensor of a nested state dict by its path."""
    if isinstance(state, torch.Tensor):
        return {prefix: state}
    items = state.items() if isinstance(state, dict) else enumerate(state) if isinstance(state, (list, tuple)) else ()
    return {k: v for key, value in items for k, v in _tensors(value, f"{prefix}/{key}").items()}
