"""State SAC (``cheetah_sac_state``, ``algo.dbc.encoder=identity``): DBC's SAC core on cheetah-run's
proprioceptive state, with no encoder and no representation losses; its config keys and end to end."""
from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from baselines.dbc import Batch, DBCAgent
from plls_bench.config import ConfigError
from plls_bench.core.atomic_files import read_json, read_jsonl
from plls_bench.rundirs.run_dir import ARCHITECTURE_FILE, PARAMS_FILE, config_hash
from tests.conftest import REPO_ROOT, compose_preset

STATE_DIM = 17  # cheetah-run: position (8) + velocity (9)
REPRESENTATION_METRICS = {"loss/encoder_bisim", "loss/transition", "loss/reward", "train/latent_batch_std"}


def state_agent(runs_dir: Path, obs_dim: int = STATE_DIM) -> DBCAgent:
    cfg = compose_preset("cheetah_sac_state", runs_dir, "algo.dbc.hidden_dim=32").algo.dbc
    return DBCAgent((obs_dim,), 6, cfg)


def state_batch(n: int = 8) -> Batch:
    g = torch.Generator().manual_seed(0)
    obs = torch.randn(n, STATE_DIM, generator=g)
    return Batch(obs=obs, action=torch.rand(n, 6, generator=g) * 2 - 1, reward=torch.rand(n, 1, generator=g),
                 next_obs=obs.flip(0), not_done=torch.ones(n, 1))


def test_the_preset_is_dbcs_sac_on_states(runs_dir: Path) -> None:
    sac, dbc = (compose_preset(p, runs_dir, "budget=quick") for p in ("cheetah_sac_state", "cheetah_dbc"))
    # no action repeat: the published state-SAC protocol (DrQ's author in denisyarats/drq issue #14), unlike
    # DBC's launcher's 2 (docs/decisions.md#d27)
    assert (sac.runner, sac.algo.dbc.encoder, sac.env.pixels, sac.env.action_repeat) == ("dbc", "identity", False, 1)
    assert dbc.env.action_repeat == 2
    assert dataclass_fields(sac.algo.dbc, "encoder") == dataclass_fields(dbc.algo.dbc, "encoder"), \
        "every SAC setting is DBC's"
    budget = sac.budget
    assert (budget.trials, budget.train_env_steps, budget.eval_every_env_steps, budget.eval_episodes) == \
        (5, 100_000, 10_000, 10)


def dataclass_fields(obj: object, *leave_out: str) -> dict[str, object]:
    return {k: v for k, v in vars(obj).items() if k not in leave_out}


def test_state_sac_has_no_encoder_and_no_representation_models(runs_dir: Path) -> None:
    agent = state_agent(runs_dir)
    assert set(agent.modules()) == {"actor", "critic", "critic_target"}
    assert set(agent.optimizers) == {"actor", "critic", "alpha"}
    x = state_batch().obs
    assert torch.equal(agent.critic.encoder(x), x) and torch.equal(agent.actor.encoder.features(x), x)
    assert agent.actor.trunk[0].in_features == STATE_DIM and agent.critic.q1[0].in_features == STATE_DIM + 6
    before = copy.deepcopy(agent.critic_target)
    metrics = agent.update(state_batch(), step=2)
    assert not REPRESENTATION_METRICS & set(metrics) and {"loss/critic", "loss/actor", "loss/alpha"} <= set(metrics)
    assert not torch.equal(before.q1[0].weight, agent.critic_target.q1[0].weight), "targets still updated"


def test_state_sac_checkpoint_restores_identical_learning(runs_dir: Path) -> None:
    torch.manual_seed(0)
    agent = state_agent(runs_dir)
    agent.update(state_batch(), step=2)
    torch.manual_seed(1)
    clone = state_agent(runs_dir)
    clone.load_state_dict(copy.deepcopy(agent.state_dict()))
    for a in (agent, clone):
        torch.manual_seed(5)
        a.update(state_batch(), step=4)
    for name, module in agent.modules().items():
        assert all(torch.equal(p, q) for p, q in zip(module.parameters(), clone.modules()[name].parameters())), name


@pytest.mark.parametrize("override, key", [
    ("env.pixels=depth", "env.pixels"),
    ("algo.dbc.encoder=depth", "algo.dbc.encoder"),
    ("env.pixels=true", "algo.dbc.encoder"),  # identity needs state vectors
])
def test_bad_state_sac_settings_are_refused_in_one_line(override: str, key: str, runs_dir: Path) -> None:
    with pytest.raises(ConfigError) as err:
        compose_preset("cheetah_sac_state", runs_dir, override)
    message = str(err.value)
    assert key in message and len(message.splitlines()) == 1, message


def test_the_encoder_key_leaves_dbc_hashes_unchanged(runs_dir: Path) -> None:
    """``algo.dbc.encoder`` at its default (bisim) is left out of the hash: DBC runs recorded before
    the key keep their identity; identity is hashed like any other value."""
    for preset in ("cheetah_dbc", "cheetah_plls_dbc"):
        plain = compose_preset(preset, runs_dir)
        assert config_hash(plain) == config_hash(compose_preset(preset, runs_dir, "algo.dbc.encoder=bisim"))
        assert config_hash(plain) != config_hash(compose_preset(preset, runs_dir, "algo.dbc.encoder=identity",
                                                                "env.pixels=false"))


@pytest.mark.slow
def test_cheetah_sac_state_end_to_end_at_smoke(runs_dir: Path) -> None:
    """The preset through the CLI at smoke budget: states in, three evaluations out, only SAC's
    losses logged, a checkpoint without representation models."""
    done = subprocess.run([sys.executable, "-m", "plls_bench", "+experiment=cheetah_sac_state", "budget=smoke",
                           f"runs_dir={runs_dir}", "progress=false"], cwd=REPO_ROOT, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    run_dir = runs_dir / "cheetah_sac_state" / "default" / "seed=0"
    assert read_json(run_dir / "status.json")["state"] == "done"
    evals = read_jsonl(run_dir / "metrics" / "eval.jsonl")
    assert [r["env_steps"] for r in evals] == [0, 200, 400]
    assert all(r["agent_steps"] == r["env_steps"] and r["episode_lengths"] == [50] for r in evals), "action repeat 1"
    train = read_jsonl(run_dir / "metrics" / "train.jsonl")
    assert "loss/critic" in train[-1] and not REPRESENTATION_METRICS & set(train[-1])
    params = read_json(run_dir / PARAMS_FILE)
    assert set(params["modules"]) == {"actor", "critic", "critic_target"}
    architecture = read_json(run_dir / ARCHITECTURE_FILE)
    first = architecture["actor"][0]
    assert (first["type"], first["output_shape"]) == ("Identity", [1, STATE_DIM]), "the 17-D state, no encoder"
    state = torch.load(run_dir / "checkpoints" / "dbc.pt", weights_only=True)
    assert set(state["agent"]["modules"]) == {"actor", "critic", "critic_target"}
