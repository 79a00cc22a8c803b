"""The DBC agent: the reference's update schedule, what each loss may train, checkpoint state,
and that the whole update learns a contextual bandit a random policy cannot solve."""
from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import torch

from baselines.dbc import Batch, DBCAgent
from baselines.dbc.bisim import latent_batch_std
from tests.conftest import compose_preset

STEPS = 600  # measured: 0.97 after 600 updates, a random policy 0.17-0.22


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def small_cfg(runs_dir: Path, *overrides: str):
    return compose_preset("cheetah_dbc", runs_dir, "algo.dbc.hidden_dim=32", "algo.dbc.encoder_feature_dim=8",
                          "algo.dbc.model_hidden_dim=32", "algo.dbc.num_filters=4", *overrides).algo.dbc


def pixel_batch(n: int = 8, action_dim: int = 6) -> Batch:
    g = torch.Generator().manual_seed(0)
    obs = torch.randint(0, 255, (n, 9, 84, 84), dtype=torch.uint8, generator=g)
    return Batch(obs=obs, action=torch.rand(n, action_dim, generator=g) * 2 - 1,
                 reward=torch.rand(n, 1, generator=g), next_obs=obs.flip(0), not_done=torch.ones(n, 1))


def params(module: torch.nn.Module) -> list[torch.Tensor]:
    return [p.detach().clone() for p in module.parameters()]


def changed(before: list[torch.Tensor], module: torch.nn.Module) -> bool:
    return any(not torch.equal(a, b) for a, b in zip(before, module.parameters()))


def test_actor_and_targets_update_every_second_agent_step(runs_dir: Path) -> None:
    agent = DBCAgent((9, 84, 84), 6, small_cfg(runs_dir))
    batch = pixel_batch()
    actor, target, alpha = params(agent.actor.trunk), params(agent.critic_target), agent.log_alpha.item()
    metrics = agent.update(batch, step=1)
    assert not changed(actor, agent.actor.trunk) and not changed(target, agent.critic_target)
    assert agent.log_alpha.item() == alpha and "loss/actor" not in metrics
    metrics = agent.update(batch, step=2)
    assert changed(actor, agent.actor.trunk) and changed(target, agent.critic_target)
    assert agent.log_alpha.item() != alpha
    assert {"loss/critic", "loss/actor", "loss/alpha", "loss/encoder_bisim", "loss/transition",
            "loss/reward", "train/latent_batch_std"} <= set(metrics)


def test_latent_batch_std_reads_zero_for_a_collapsed_encoder_and_not_for_a_spread_one() -> None:
    spread = torch.nn.functional.layer_norm(torch.randn(128, 50), (50,))
    collapsed = spread[:1].expand(128, 50) + 1e-6 * torch.randn(128, 50)
    assert latent_batch_std(collapsed) < 1e-4 < 0.5 < latent_batch_std(spread)


def test_actor_loss_never_trains_the_shared_conv_trunk(runs_dir: Path) -> None:
    agent = DBCAgent((9, 84, 84), 6, small_cfg(runs_dir))
    assert agent.actor.encoder.trunk is agent.critic.encoder.trunk, "conv weights are shared"
    trunk, head = params(agent.critic.encoder.trunk), params(agent.actor.encoder.fc)
    agent.update_actor_and_alpha(pixel_batch().obs)
    assert not changed(trunk, agent.critic.encoder.trunk)
    assert changed(head, agent.actor.encoder.fc), "the actor's own Linear + LayerNorm head is trained"


def test_soft_target_update_moves_by_tau(runs_dir: Path) -> None:
    cfg = small_cfg(runs_dir)
    agent = DBCAgent((9, 84, 84), 6, cfg)
    before = copy.deepcopy(agent.critic_target)
    agent.update(pixel_batch(), step=2)
    q, q_old, q_target = agent.critic.q1[0].weight, before.q1[0].weight, agent.critic_target.q1[0].weight
    assert torch.allclose(q_target, q_old + cfg.critic_tau * (q - q_old), atol=1e-6)
    enc, enc_old, enc_target = (agent.critic.encoder.fc.weight, before.encoder.fc.weight,
                                agent.critic_target.encoder.fc.weight)
    assert torch.allclose(enc_target, enc_old + cfg.encoder_tau * (enc - enc_old), atol=1e-6)


@pytest.mark.parametrize("encoder", ["bisim", "critic"])  # critic: pixel SAC, no representation models
def test_checkpoint_state_restores_identical_learning(encoder: str, runs_dir: Path) -> None:
    cfg = small_cfg(runs_dir, f"algo.dbc.encoder={encoder}")
    torch.manual_seed(0)
    agent = DBCAgent((9, 84, 84), 6, cfg)
    for step in range(3):
        agent.update(pixel_batch(), step)
    torch.manual_seed(1)
    clone = DBCAgent((9, 84, 84), 6, cfg)
    clone.load_state_dict(copy.deepcopy(agent.state_dict()))
    for a in (agent, clone):
        torch.manual_seed(5)
        a.update(pixel_batch(), step=4)
    for name, module in agent.modules().items():
        for p, q in zip(module.parameters(), clone.modules()[name].parameters()):
            assert torch.equal(p, q), name
    assert agent.log_alpha.item() == clone.log_alpha.item()


@pytest.mark.parametrize("encoder", ["bisim", "critic", "identity"])
def test_learns_a_contextual_bandit_from_random_actions(encoder: str, runs_dir: Path) -> None:
    """Reward 1 - ||a - tanh(W x)||^2 / A for context x: a random policy gets about 0.2; the
    whole update (critic, actor, temperature, representation losses with ``bisim``; the same encoder
    trained by the critic alone with ``critic``; state SAC's critic, actor and temperature alone with
    ``identity``) must get close to 1."""
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    dim, action_dim, n = 4, 2, 4096
    w = rng.normal(size=(dim, action_dim))
    x = rng.normal(size=(n, dim)).astype(np.float32)
    best = np.tanh(x @ w)
    actions = rng.uniform(-1, 1, size=(n, action_dim)).astype(np.float32)

    def reward(a: np.ndarray, ctx: np.ndarray) -> np.ndarray:
        return 1.0 - ((a - np.tanh(ctx @ w)) ** 2).mean(axis=1)

    rewards = reward(actions, x).astype(np.float32)
    agent = DBCAgent((dim,), action_dim, small_cfg(runs_dir, "algo.dbc.encoder_feature_dim=16",
                                                   "algo.dbc.hidden_dim=64",
                                                   "algo.dbc.batch_size=128", f"algo.dbc.encoder={encoder}",
                                                   "env.pixels=false"))
    for step in range(STEPS):
        i = rng.integers(n, size=128)
        agent.update(Batch(obs=torch.as_tensor(x[i]), action=torch.as_tensor(actions[i]),
                           reward=torch.as_tensor(rewards[i, None]), next_obs=torch.as_tensor(x[i]),
                           not_done=torch.zeros(128, 1)), step)
    test_x = rng.normal(size=(500, dim)).astype(np.float32)
    learned = reward(agent.act(test_x, deterministic=True), test_x).mean()
    random_policy = reward(rng.uniform(-1, 1, size=(500, action_dim)), test_x).mean()
    assert reward(best[:1], x[:1]) == pytest.approx(1.0)
    assert random_policy < 0.5 and learned > 0.9, (learned, random_policy)


def test_accounting_counts_shared_conv_weights_once(runs_dir: Path) -> None:
    from plls_bench.envs import make_vec_env
    from plls_bench.train.dbc_accounting import accounting

    cfg = compose_preset("cheetah_dbc", runs_dir, "algo.dbc.num_filters=4", "algo.dbc.hidden_dim=32")
    agent = DBCAgent((9, 84, 84), 6, cfg.algo.dbc)
    venv = make_vec_env(cfg.env, 1, 0)
    try:
        params, architecture = accounting(agent, venv)
    finally:
        venv.close()
    every = {id(p): p.numel() for m in agent.modules().values() for p in m.parameters()}
    assert params["total"] == sum(every.values()), "each parameter once, the shared trunk included"
    assert params["trainable"] == params["total"] - params["modules"]["critic_target"]["total"]
    conv = [row for row in architecture["encoder"] if row["type"] == "Conv2d"]
    assert conv[0]["output_shape"] == [1, 4, 41, 41] and conv[-1]["output_shape"] == [1, 4, 35, 35]
    assert architecture["encoder"][-1]["type"] == "LayerNorm" and architecture["encoder"][-1]["output_shape"] == [1, 50]
    assert architecture["actor"][-1]["output_shape"] == [1, 12], "mean and log-std of 6 actions"
    assert all(row["trainable"] == 0 for row in architecture["critic_target"])
