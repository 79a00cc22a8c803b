"""Loading a model never draws from torch's global RNG: a module built only to receive weights
(V_s, V_a, a trained policy) takes its throw-away initial weights from a fork of the stream, so how
often anything was loaded before never changes what the runner's seed produces."""
from __future__ import annotations

from pathlib import Path

import torch

from plls_bench.config import Config
from plls_bench.core.seeding import derive_seeds, seed_everything
from plls_bench.repr.store import ensure_representations, load_representations
from plls_bench.rundirs.run_dir import Run, config_hash
from plls_bench.train.loop import Progress
from plls_bench.train.ppo import PPOTrainer
from tests.conftest import compose_preset


def trainer_policy(cfg: Config, run_dir: Path, loads_before: int) -> dict[str, torch.Tensor]:
    """The initial policy weights of a fresh PPO trial, built as the runner builds it (seeded from
    the trial's training seed, then the trainer's setup and restore), after ``loads_before``
    extra loads of its V_a."""
    seed_everything(derive_seeds(cfg.seed, cfg.data_seed, cfg.repr.per_trial).train)  # as runner.execute
    for _ in range(loads_before):
        assert load_representations(cfg).action_vae is not None
    trainer = PPOTrainer(cfg, Run(run_dir))
    trainer.setup()
    try:
        assert trainer.restore() is None, "a fresh trial"
        return {name: t.detach().clone() for name, t in trainer.model.policy.state_dict().items()}
    finally:
        trainer.close()


def test_policy_init_is_the_same_whether_va_was_loaded_zero_one_or_two_times(runs_dir: Path) -> None:
    cfg = compose_preset("mountaincar_plls_ppo", runs_dir)
    ensure_representations(cfg)  # the tiny smoke-budget V_a, built once
    weights = [trainer_policy(cfg, runs_dir / f"trial{k}", k) for k in range(3)]
    for other in weights[1:]:
        assert other.keys() == weights[0].keys()
        assert all(torch.equal(other[name], weights[0][name]) for name in weights[0])


def test_every_load_function_leaves_the_global_rng_where_it_was(runs_dir: Path) -> None:
    from plls_bench.train.ppo_model import load_trained

    cfg = compose_preset("mountaincar_plls_ppo", runs_dir)
    ensure_representations(cfg)
    run_dir = runs_dir / "ppo"
    trainer = PPOTrainer(cfg, Run(run_dir))
    trainer.setup()
    trainer.restore()
    Run(run_dir).prepare(cfg, config_hash(cfg))
    trainer.checkpoint(Progress())
    trainer.close()
    torch.manual_seed(7)
    for load in (lambda: load_representations(cfg), lambda: load_trained(run_dir, device="cpu")):
        before = torch.random.get_rng_state()
        load()
        assert torch.equal(torch.random.get_rng_state(), before)


def test_loading_a_dbc_agent_leaves_the_global_rng_where_it_was(runs_dir: Path) -> None:
    from baselines.dbc import DBCAgent
    from plls_bench.train.dbc_state import CHECKPOINT, load_trained_agent

    cfg = compose_preset("cheetah_dbc", runs_dir)
    run = Run(runs_dir / "dbc")
    run.prepare(cfg, config_hash(cfg))
    obs_shape = (3 * cfg.env.frame_stack, cfg.env.image_size, cfg.env.image_size)
    assert cfg.algo.dbc is not None
    torch.save({"agent": DBCAgent(obs_shape, 6, cfg.algo.dbc).state_dict()}, run.path / CHECKPOINT)
    torch.manual_seed(7)
    before = torch.random.get_rng_state()
    load_trained_agent(run.path, device="cpu")
    assert torch.equal(torch.random.get_rng_state(), before)
