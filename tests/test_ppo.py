"""PPO runner: the paper's networks, budgets in iterations, evaluation, end-to-end presets, resume."""
from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.vec_env import DummyVecEnv
from torch import nn

from plls_bench.config import Config
from plls_bench.envs import make_env
from plls_bench.envs.evaluation import run_episodes
from plls_bench.rundirs.composition import compose
from plls_bench.rundirs.run_dir import HASH_EXCLUDED_KEYS, HASH_PLAN_KEYS, config_dict
from plls_bench.train.networks import PaperCNN, SharedMLP, policy_kwargs
from plls_bench.train.ppo_model import build_vec_env
from plls_bench.train.schedule import Schedule
from tests.conftest import compose_preset

PPO_PRESETS = ["mountaincar_ppo", "mountaincar_plls_ppo", "carracing_ppo", "carracing_plls_ppo",
               "carracing_ppo_vs", "carracing_ppo_va"]


def policy_spaces(cfg: Config) -> tuple[gym.spaces.Box, gym.spaces.Box]:
    """What the policy sees and emits: the env's own spaces, or V_s's z and V_a's e."""
    env = make_env(cfg.env)
    obs, act = env.observation_space, env.action_space
    env.close()
    if cfg.repr.state.kind == "vae":
        obs = gym.spaces.Box(-np.inf, np.inf, (cfg.repr.state.latent_dim,), np.float32)
    if cfg.repr.action.kind == "vae":
        bound = cfg.repr.action.latent_action_bound
        act = gym.spaces.Box(-bound, bound, (cfg.repr.action.latent_dim,), np.float32)
    return obs, act


def build_policy(cfg: Config) -> ActorCriticPolicy:
    assert cfg.algo.ppo is not None
    obs, act = policy_spaces(cfg)
    return ActorCriticPolicy(obs, act, lambda _: cfg.algo.ppo.learning_rate, **policy_kwargs(cfg.algo.ppo))


def linear_widths(module: nn.Module) -> list[tuple[int, int]]:
    return [(m.in_features, m.out_features) for m in module.modules() if isinstance(m, nn.Linear)]


# --------------------------------------------------------------------------- networks
@pytest.mark.parametrize("preset", PPO_PRESETS)
def test_policy_and_value_share_one_trunk_with_linear_heads(preset: str) -> None:
    cfg = compose([f"+experiment={preset}", "budget=paper"])
    policy = build_policy(cfg)
    assert policy.pi_features_extractor is policy.vf_features_extractor is policy.features_extractor
    assert sum(p.numel() for p in policy.mlp_extractor.parameters()) == 0, "no separate pi/vf MLPs"
    trunk_out = policy.features_extractor.features_dim
    assert linear_widths(policy.action_net) == [(trunk_out, policy.action_space.shape[0])]
    assert linear_widths(policy.value_net) == [(trunk_out, 1)]


def test_mountaincar_trunk_is_the_papers_128_64_mlp() -> None:
    cfg = compose(["+experiment=mountaincar_ppo", "budget=paper"])
    trunk = build_policy(cfg).features_extractor
    assert isinstance(trunk, SharedMLP)
    assert cfg.algo.ppo is not None and cfg.algo.ppo.policy_hidden == [128, 64]  # Sec. 5.1
    assert linear_widths(trunk) == [(2, 128), (128, 64)]


def test_carracing_plain_ppo_is_four_conv_two_fc_as_configured() -> None:
    cfg = compose(["+experiment=carracing_ppo", "budget=paper"])
    ppo = cfg.algo.ppo
    assert ppo is not None
    trunk = build_policy(cfg).features_extractor
    assert isinstance(trunk, PaperCNN)
    convs = [m for m in trunk.modules() if isinstance(m, nn.Conv2d)]
    assert [c.out_channels for c in convs] == ppo.cnn_channels and len(convs) == 4
    assert [c.kernel_size for c in convs] == [(k, k) for k in ppo.cnn_kernel_sizes]
    assert all(c.stride == (ppo.cnn_stride, ppo.cnn_stride) for c in convs)
    flat = ppo.cnn_channels[-1] * 4 * 4  # 96 -> 47 -> 22 -> 10 -> 4 at kernel 4, stride 2
    assert linear_widths(trunk) == [(flat, ppo.cnn_hidden[0]), (ppo.cnn_hidden[0], ppo.cnn_hidden[1])]


@pytest.mark.parametrize(("overrides", "paper_trainable"), [
    (["+experiment=carracing_ppo"], 1_644_878),
    (["+experiment=carracing_plls_ppo"], 4354),
], ids=["plain_ppo", "pl_ls"])
def test_policy_sizes_are_half_of_table_3(overrides: list[str], paper_trainable: int) -> None:
    """Table 3 counts two copies of each policy (current and old, see docs/methods.md, "Parameter
    counts (Table 3)"); one copy of ours has exactly half its trainable parameters."""
    policy = build_policy(compose([*overrides, "budget=paper"]))
    assert 2 * sum(p.numel() for p in policy.parameters()) == paper_trainable


def _flat(tree: dict, prefix: str = "") -> dict[str, object]:
    out: dict[str, object] = {}
    for key, value in tree.items():
        out.update(_flat(value, f"{prefix}{key}.") if isinstance(value, dict) else {f"{prefix}{key}": value})
    return out


@pytest.mark.parametrize(("presets", "may_differ"), [
    (["carracing_plls_ppo", "carracing_ppo", "carracing_ppo_vs", "carracing_ppo_va"],
     ("repr.state.", "repr.action.", "algo.ppo.features_extractor")),
    (["mountaincar_plls_ppo", "mountaincar_ppo"], ("repr.action.", "algo.ppo.learning_rate")),
], ids=["carracing", "mountaincar"])
def test_methods_of_a_task_differ_only_in_representations_and_network(presets: list[str],
                                                                      may_differ: tuple[str, ...]) -> None:
    """Same Table 1 / Table 2 settings for every method of a task (Sec. 5.1, 5.2); only V_s / V_a,
    the trunk the observations need, and plain PPO's MountainCar learning rate change."""
    configs = [_flat(config_dict(compose([f"+experiment={p}", "budget=paper"]))) for p in presets]
    for other in configs[1:]:
        # names, speed knobs (torch_threads) and trial counts, which follow each arm's claims rows' plans
        ignored = {"experiment", *HASH_EXCLUDED_KEYS, *HASH_PLAN_KEYS}
        differing = {k for k in configs[0] if configs[0][k] != other[k]} - ignored
        assert differing and all(k.startswith(may_differ) for k in differing), differing


def test_a_trunk_that_does_not_fit_the_observations_is_refused() -> None:
    with pytest.raises(Exception, match="algo.ppo.features_extractor"):
        compose(["+experiment=carracing_ppo", "algo.ppo.features_extractor=mlp"])


# --------------------------------------------------------------------------- budgets
@pytest.mark.parametrize(("env", "budget", "iterations", "eval_every"), [
    ("mountaincar", "paper", 1500, 10), ("mountaincar", "quick", 100, 5), ("mountaincar", "smoke", 2, 1),
    ("carracing", "paper", 120, 2), ("carracing", "quick", 64, 4), ("carracing", "smoke", 2, 1),
])
def test_budgets_in_ppo_iterations(env: str, budget: str, iterations: int, eval_every: int) -> None:
    plan = Schedule.of(compose([f"+experiment={env}_ppo", f"budget={budget}"]))
    assert (plan.iterations, plan.eval_every) == (iterations, eval_every)
    assert plan.eval_at(0) and plan.eval_at(iterations)


# --------------------------------------------------------------------------- evaluation
def _pump(obs: np.ndarray) -> np.ndarray:
    """A MountainCar policy that reaches the goal: push along the velocity."""
    return np.where(obs[:, 1:2] >= 0, 1.0, -1.0).astype(np.float32)


def test_episode_j_is_seeded_the_same_whatever_the_number_of_envs(runs_dir: Path) -> None:
    cfg = compose_preset("mountaincar_ppo", runs_dir)
    results = []
    for n_envs in (1, 3):
        venv = build_vec_env(cfg, n_envs, seed=0)
        results.append(run_episodes(venv, _pump, n_episodes=4, seed=123))
        venv.close()
    assert results[0] == results[1]
    assert all(r > 80 for r in results[0].returns), "the pumping policy reaches the goal (+100)"
    assert len(set(results[0].lengths)) > 1, "different seeds, different start states"


def test_episode_cap_cuts_test_episodes(runs_dir: Path) -> None:
    cfg = compose_preset("mountaincar_ppo", runs_dir)
    venv = DummyVecEnv([lambda: make_env(cfg.env)] * 2)
    episodes = run_episodes(venv, lambda o: np.zeros((len(o), 1), np.float32), 3, seed=0, max_steps=7)
    assert episodes.lengths == [7, 7, 7]
