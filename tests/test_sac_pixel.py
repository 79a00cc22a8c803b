"""Pixel SAC (``cheetah_sac_pixel``, ``algo.dbc.encoder=critic``): DBC's SAC core and pixel encoder with
the encoder trained by the critic alone, no representation losses; its config keys and end to end."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import torch

from baselines.dbc import Batch, DBCAgent
from plls_bench.core.atomic_files import read_json, read_jsonl
from plls_bench.rundirs.run_dir import ARCHITECTURE_FILE, PARAMS_FILE, config_hash
from tests.conftest import REPO_ROOT, compose_preset

REPRESENTATION_LOSSES = {"loss/encoder_bisim", "loss/transition", "loss/reward"}
OBS = (9, 84, 84)  # frame stack 3 of 84x84 RGB


def pixel_agent(runs_dir: Path) -> DBCAgent:
    cfg = compose_preset("cheetah_sac_pixel", runs_dir, "algo.dbc.hidden_dim=32", "algo.dbc.num_filters=4")
    return DBCAgent(OBS, 6, cfg.algo.dbc)


def pixel_batch(n: int = 8) -> Batch:
    g = torch.Generator().manual_seed(0)
    obs = torch.randint(0, 255, (n, *OBS), dtype=torch.uint8, generator=g)
    return Batch(obs=obs, action=torch.rand(n, 6, generator=g) * 2 - 1, reward=torch.rand(n, 1, generator=g),
                 next_obs=obs.flip(0), not_done=torch.ones(n, 1))


def params(module: torch.nn.Module) -> list[torch.Tensor]:
    return [p.detach().clone() for p in module.parameters()]


def changed(before: list[torch.Tensor], module: torch.nn.Module) -> bool:
    return any(not torch.equal(a, b) for a, b in zip(before, module.parameters()))


@pytest.mark.parametrize("profile", ["quick", "paper"])
def test_the_preset_is_dbcs_sac_and_encoder_without_bisimulation(profile: str, runs_dir: Path) -> None:
    sac, dbc = (compose_preset(p, runs_dir, f"budget={profile}") for p in ("cheetah_sac_pixel", "cheetah_dbc"))
    assert (sac.runner, sac.algo.dbc.encoder, sac.env.pixels) == ("dbc", "critic", True)
    # CURL's pixel agents' action repeat for cheetah (its Table 3), not the DBC launchers' 2
    assert (sac.env.action_repeat, dbc.env.action_repeat) == (4, 2)
    same = {k: v for k, v in vars(dbc.algo.dbc).items() if k != "encoder"}
    assert {k: v for k, v in vars(sac.algo.dbc).items() if k != "encoder"} == same, "every other setting is DBC's"
    assert {k: v for k, v in vars(sac.env).items() if k != "action_repeat"} == \
        {k: v for k, v in vars(dbc.env).items() if k != "action_repeat"}, "the same pixels, frame stack and camera"
    budget = sac.budget
    assert (budget.trials, budget.train_env_steps, budget.eval_every_env_steps, budget.eval_episodes) == \
        (3, 100_000, 10_000, 10)


def test_the_encoder_is_trained_by_the_critic_alone(runs_dir: Path) -> None:
    agent = pixel_agent(runs_dir)
    assert set(agent.modules()) == {"actor", "critic", "critic_target"}, "no transition model, no reward decoder"
    assert set(agent.optimizers) == {"actor", "critic", "alpha"}, "no encoder or decoder optimiser"
    assert agent.actor.encoder.trunk is agent.critic.encoder.trunk, "conv weights shared, as DBC's"
    trunk, head = params(agent.critic.encoder.trunk), params(agent.critic.encoder.fc)
    metrics = agent.update(pixel_batch(), step=1)  # odd step: the critic's update only
    assert changed(trunk, agent.critic.encoder.trunk) and changed(head, agent.critic.encoder.fc)
    assert set(metrics) == {"loss/critic", "train/batch_reward"}
    trunk = params(agent.critic.encoder.trunk)
    metrics = agent.update_actor_and_alpha(pixel_batch().obs)
    assert not changed(trunk, agent.critic.encoder.trunk), "the actor never trains the shared trunk"
    assert not REPRESENTATION_LOSSES & set(metrics) and 0.0 < metrics["train/latent_batch_std"] < 2.0


def test_the_critic_encoder_is_hashed(runs_dir: Path) -> None:
    """``encoder=critic`` is not the neutral default (bisim): a pixel-SAC run never shares DBC's identity."""
    dbc = compose_preset("cheetah_dbc", runs_dir, "env.action_repeat=4")
    assert config_hash(dbc) != config_hash(compose_preset("cheetah_dbc", runs_dir, "env.action_repeat=4",
                                                          "algo.dbc.encoder=critic"))


@pytest.mark.slow
def test_cheetah_sac_pixel_end_to_end_at_smoke(runs_dir: Path) -> None:
    """The preset through the CLI at smoke budget: pixels in, three evaluations out, only SAC's losses
    and the critic latent's spread logged, an encoder but no representation models in the checkpoint."""
    done = subprocess.run([sys.executable, "-m", "plls_bench", "+experiment=cheetah_sac_pixel", "budget=smoke",
                           f"runs_dir={runs_dir}", "progress=false", "torch_threads=1"], cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    run_dir = runs_dir / "cheetah_sac_pixel" / "default" / "seed=0"
    assert read_json(run_dir / "status.json")["state"] == "done"
    evals = read_jsonl(run_dir / "metrics" / "eval.jsonl")
    assert [r["env_steps"] for r in evals] == [0, 200, 400]
    assert all(r["agent_steps"] * 4 == r["env_steps"] and r["episode_lengths"] == [50] for r in evals), "repeat 4"
    train = read_jsonl(run_dir / "metrics" / "train.jsonl")
    assert {"loss/critic", "loss/actor", "train/latent_batch_std"} <= set(train[-1])
    assert not REPRESENTATION_LOSSES & set(train[-1])
    params_json = read_json(run_dir / PARAMS_FILE)
    assert set(params_json["modules"]) == {"encoder", "actor", "critic", "critic_target"}
    convs = [row for row in read_json(run_dir / ARCHITECTURE_FILE)["encoder"] if row["type"] == "Conv2d"]
    assert [c["output_shape"] for c in convs] == [[1, 32, 41, 41], [1, 32, 39, 39], [1, 32, 37, 37], [1, 32, 35, 35]]
    state = torch.load(run_dir / "checkpoints" / "dbc.pt", weights_only=True)
    assert set(state["agent"]["modules"]) == {"actor", "critic", "critic_target"}
