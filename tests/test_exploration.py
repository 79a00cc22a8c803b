"""Exploration and normalisation, the PPO settings the paper leaves open: algo/exploration,
gSDE, VecNormalize saved with every checkpoint, restored on resume and frozen at evaluation."""
from __future__ import annotations

import json
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from stable_baselines3.common.vec_env import VecNormalize

from plls_bench.core.atomic_files import read_jsonl
from plls_bench.core.seeding import derive_seeds
from plls_bench.rundirs.run_dir import HASH_EXCLUDED_KEYS, Run, config_dict, config_hash, stable_hash
from plls_bench.train import checkpoint, normalize, ppo
from plls_bench.train.ppo_model import build_vec_env, load_trained, new_model
from plls_bench.train.schedule import Schedule
from tests.conftest import compose_preset, run_cli, start_cli

NEW_PPO_KEYS = ("use_sde", "sde_sample_freq", "normalize_obs", "normalize_reward")
NORMALISED = ["algo.ppo.normalize_obs=true", "algo.ppo.normalize_reward=true"]


def test_exploration_choice_reaches_sb3(tmp_path: Path) -> None:
    for choice, sde in (("gaussian", False), ("gsde", True)):
        cfg = compose_preset("mountaincar_ppo", tmp_path, f"algo/exploration={choice}")
        venv = build_vec_env(cfg, 1, seed=0)
        model = new_model(cfg, venv)
        venv.close()
        assert cfg.algo.ppo.use_sde is sde and model.use_sde is sde and model.policy.use_sde is sde


def test_literal_runs_keep_their_config_hash(tmp_path: Path) -> None:
    """The new keys at their off values hash as the configs recorded before they existed."""
    cfg = compose_preset("mountaincar_ppo", tmp_path)
    old = {**config_dict(cfg), "device": "cpu"}  # the default before device=auto
    for key in NEW_PPO_KEYS:
        del old["algo"]["ppo"][key]
    for key in ("backend", "backend_threads", "visuals"):  # env keys newer than those runs too
        del old["env"][key]
    del old["precision"]  # newer than those runs too
    del old["budget"]["trials"]  # the plan's, never hashed since (runs.HASH_PLAN_KEYS; old records are re-hashed)
    old_hash = stable_hash({k: v for k, v in old.items() if k not in HASH_EXCLUDED_KEYS})
    assert config_hash(cfg) == old_hash
    assert config_hash(compose_preset("mountaincar_ppo", tmp_path, "algo/exploration=gaussian")) == old_hash
    assert config_hash(compose_preset("mountaincar_ppo", tmp_path, "algo/exploration=gsde")) != old_hash
    assert config_hash(compose_preset("mountaincar_ppo_gsde", tmp_path)) != old_hash


def test_zoo_preset_carries_the_zoo_recipe(tmp_path: Path) -> None:
    """rl-baselines3-zoo hyperparams/ppo.yml, MountainCarContinuous-v0, at its 20k-step budget."""
    cfg = compose_preset("mountaincar_ppo_zoo", tmp_path, "budget=quick")
    p = cfg.algo.ppo
    assert (p.n_envs, p.n_steps, p.gamma, p.gae_lambda, p.learning_rate) == (1, 8, 0.9999, 0.9, 7.77e-05)
    assert (p.ent_coef, p.clip_range, p.n_epochs, p.max_grad_norm, p.vf_coef) == (0.00429, 0.1, 10, 5.0, 0.19)
    assert (p.use_sde, p.log_std_init, p.ortho_init) == (True, -3.29, False)
    assert (p.normalize_obs, p.normalize_reward) == (True, True)
    assert p.features_extractor == "separate_mlp" and cfg.budget.train_env_steps == 20000 and cfg.budget.trials == 10
    venv = normalize.wrap_training(build_vec_env(cfg, 1, seed=0), p)
    model = new_model(cfg, venv)
    venv.close()
    assert isinstance(venv, VecNormalize) and venv.gamma == 0.9999
    widths = [[m.out_features for m in net if hasattr(m, "out_features")]
              for net in (model.policy.mlp_extractor.policy_net, model.policy.mlp_extractor.value_net)]
    assert widths == [[64, 64], [64, 64]], "SB3's MlpPolicy: separate pi and vf MLPs"


def test_gsde_preset_budget_is_seven_trials_of_200_iterations_at_quick(tmp_path: Path) -> None:
    for preset in ("mountaincar_ppo_gsde", "mountaincar_plls_ppo_gsde"):
        cfg = compose_preset(preset, tmp_path, "budget=quick")
        assert cfg.budget.trials == 7 and Schedule.of(cfg).iterations == 200
    assert Schedule.of(compose_preset("mountaincar_ppo", tmp_path, "budget=quick")).iterations == 100


def test_carracing_gsde_presets_take_only_the_zoo_exploration_keys(tmp_path: Path) -> None:
    """rl-baselines3-zoo's CarRacing recipe explores with gSDE (sde_sample_freq 4, log_std_init -2);
    every other key stays the Gaussian preset's (Table 2), at the matched quick budget with 5 trials."""
    for preset in ("carracing_ppo", "carracing_plls_ppo"):
        gauss, gsde = (compose_preset(name, tmp_path, "budget=quick") for name in (preset, f"{preset}_gsde"))
        p = gsde.algo.ppo
        assert (p.use_sde, p.sde_sample_freq, p.log_std_init) == (True, 4, -2.0)
        exploration = ("use_sde", "sde_sample_freq", "log_std_init")
        assert {k: v for k, v in vars(p).items() if k not in exploration} == \
            {k: v for k, v in vars(gauss.algo.ppo).items() if k not in exploration}
        assert gsde.budget.train_env_steps == gauss.budget.train_env_steps == 1_024_000
        assert gsde.budget.trials == 6  # the gSDE Fig. 18 row's planned n (tests/test_claim_costs.py)
    mountaincar = compose_preset("mountaincar_ppo_gsde", tmp_path, "budget=quick").algo.ppo
    assert (mountaincar.sde_sample_freq, mountaincar.log_std_init) == (0, 0.0), "MountainCar's records keep theirs"


@pytest.mark.slow
def test_exploration_sweep_runs_into_readable_variants(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    done = run_cli("-m", "+experiment=mountaincar_ppo", "algo/exploration=gaussian,gsde", f"runs_dir={runs}",
                   "progress=false", "budget.train_env_steps=512")
    assert done.returncode == 0, done.stdout + done.stderr
    for choice, sde in (("gaussian", False), ("gsde", True)):
        run = Run(runs / "mountaincar_ppo" / f"algo.exploration={choice},budget.train_env_steps=512" / "seed=0")
        assert (run.read_status() or {}).get("state") == "done"
        assert (run.read_config() or {})["config"]["algo"]["ppo"]["use_sde"] is sde


@pytest.mark.slow
def test_normalised_run_resumes_with_its_saved_statistics(tmp_path: Path) -> None:
    """Killed after a checkpoint, the restored VecNormalize statistics equal the saved ones; the
    finished run's test episodes saw them frozen and load_trained applies them."""
    runs = tmp_path / "runs"
    args = ["+experiment=mountaincar_ppo", f"runs_dir={runs}", "progress=false", "variant=norm",
            "budget.train_env_steps=5120", "budget.eval_every_env_steps=512", *NORMALISED]
    run_dir = runs / "mountaincar_ppo" / "norm" / "seed=0"
    proc = start_cli(*args)
    deadline = time.monotonic() + 300
    while len(read_jsonl(run_dir / "metrics" / "train.jsonl")) < 4:
        assert proc.poll() is None and time.monotonic() < deadline, "run ended or stalled before the kill"
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    saved = json.loads(checkpoint.normalization(run_dir))
    assert saved["obs_rms"]["count"] > 1 and saved["ret_rms"]["count"] > 1

    cfg = compose_preset("mountaincar_ppo", runs, "budget.train_env_steps=5120",
                         "budget.eval_every_env_steps=512", *NORMALISED)
    venv = normalize.wrap_training(build_vec_env(cfg, cfg.algo.ppo.n_envs, seed=0), cfg.algo.ppo)
    model, progress, fresh = ppo._start_or_resume(cfg, Run(run_dir), venv, derive_seeds(0, 0, False).train)
    assert not fresh and progress.iteration >= 1
    for name in ("obs_rms", "ret_rms"):
        rms = getattr(venv, name)
        assert np.array_equal(rms.mean, np.asarray(saved[name]["mean"])) and rms.count == saved[name]["count"]
        assert np.array_equal(rms.var, np.asarray(saved[name]["var"]))
    venv.close()

    done = run_cli(*args)
    assert done.returncode == 0, done.stdout + done.stderr
    trained = load_trained(run_dir)
    final = json.loads(checkpoint.normalization(run_dir))
    obs = np.array([[-0.5, 0.01], [0.3, -0.02]], dtype=np.float32)
    frozen = (obs - np.asarray(final["obs_rms"]["mean"])) / np.sqrt(np.asarray(final["obs_rms"]["var"]) + 1e-8)
    np.testing.assert_allclose(trained.normalize_obs(obs), np.clip(frozen, -10, 10), rtol=1e-6)


def test_evaluation_sees_frozen_statistics_and_raw_rewards(tmp_path: Path) -> None:
    cfg = compose_preset("mountaincar_ppo", tmp_path, *NORMALISED)
    train = normalize.wrap_training(build_vec_env(cfg, 2, seed=0), cfg.algo.ppo)
    test = normalize.wrap_frozen(build_vec_env(cfg, 2, seed=1), cfg.algo.ppo)
    assert isinstance(test, VecNormalize) and not test.training and not test.norm_reward
    train.reset()
    for _ in range(20):
        train.step(np.ones((2, 1), dtype=np.float32))
    normalize.sync(train, test)
    before = test.obs_rms.copy()
    test.reset()
    obs, rewards, _, _ = test.step(np.ones((2, 1), dtype=np.float32))
    assert test.obs_rms.count == before.count and np.array_equal(test.obs_rms.mean, train.obs_rms.mean)
    np.testing.assert_allclose(rewards, -0.1, rtol=1e-5)  # MountainCar's raw -0.1 a^2, not scaled
    np.testing.assert_allclose(obs, test.normalize_obs(test.get_original_obs()), rtol=1e-6)
    train.close()
    test.close()
