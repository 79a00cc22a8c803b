"""envpool backend: SB3's episode-boundary semantics, a check_env-style check of the VecEnv,
seeding contracts, and the backend's place in hashes, artifact keys and run-dir variants."""
from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.vec_env import VecMonitor

from plls_bench.data import dataset_key
from plls_bench.data.collect import collect_random_policy
from plls_bench.envs import make_vec_env
from plls_bench.envs.envpool_backend import EnvpoolVecEnv, _make_pool
from plls_bench.envs.evaluation import run_episodes
from plls_bench.rundirs.run_dir import config_hash, variant_name
from tests.conftest import compose_preset

HORIZON = 5  # a short time limit: several episode boundaries in a few steps


def _actions(steps: int, n_envs: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.uniform([-1, 0, 0], [1, 1, 1], size=(steps, n_envs, 3)).astype(np.float32)


def test_episode_boundaries_follow_sb3_semantics() -> None:
    """Against the raw pool: envpool spends one extra step (reward 0, action ignored) resetting a
    finished env; the adapter returns the next episode's first frame on the finishing step, with
    the last frame in ``terminal_observation``, and never shows that extra step."""
    n_envs, steps = 2, 3 * HORIZON
    actions = _actions(steps, n_envs)
    adapter = EnvpoolVecEnv("CarRacing-v3", n_envs, HORIZON, seed=11)
    first = adapter.reset()
    got = [adapter.step(a) for a in actions]

    raw = _make_pool("CarRacing-v3", n_envs, [11, 12], HORIZON, 0)
    raw_obs, _ = raw.reset()
    assert np.array_equal(first, raw_obs.transpose(0, 3, 1, 2))
    t = 0
    for _episode in range(3):
        for k in range(HORIZON):
            obs, rewards, terminated, truncated, _ = raw.step(actions[t], np.arange(n_envs))
            obs_a, rewards_a, dones_a, infos_a = got[t]
            np.testing.assert_allclose(rewards_a, rewards, rtol=1e-6)
            last = k == HORIZON - 1
            assert list(dones_a) == [last] * n_envs and list(truncated) == [last] * n_envs
            if last:
                for i in range(n_envs):
                    assert np.array_equal(infos_a[i]["terminal_observation"], obs[i].transpose(2, 0, 1))
                    assert infos_a[i]["TimeLimit.truncated"] is True
                reset_obs, reset_rewards, *_ = raw.step(actions[t], np.arange(n_envs))  # envpool's extra step
                assert np.all(reset_rewards == 0)
                assert np.array_equal(obs_a, reset_obs.transpose(0, 3, 1, 2))
            else:
                assert np.array_equal(obs_a, obs.transpose(0, 3, 1, 2)) and infos_a == [{}] * n_envs
            t += 1


def test_vec_env_check() -> None:
    """What SB3's check_env asserts of an env, for the vector env: spaces, dtypes, values in the
    spaces, per-env info dicts, clipped actions, VecMonitor statistics, determinism per seed."""
    venv = VecMonitor(EnvpoolVecEnv("CarRacing-v3", 3, HORIZON, seed=4))
    assert venv.observation_space == gym.spaces.Box(0, 255, (3, 96, 96), np.uint8)  # SB3's image convention
    assert venv.action_space.shape == (3,)
    obs = venv.reset()
    assert obs.shape == (3, 3, 96, 96) and obs.dtype == np.uint8
    assert all(venv.observation_space.contains(o) for o in obs)
    total = np.zeros(3)
    for _ in range(HORIZON):
        obs, rewards, dones, infos = venv.step(np.full((3, 3), 5.0))  # out of the box: clipped
        total += rewards
        assert obs.dtype == np.uint8 and rewards.dtype == np.float32 and dones.dtype == bool
        assert isinstance(infos, list) and len(infos) == 3
    assert dones.all()
    for i, info in enumerate(infos):
        assert info["episode"]["l"] == HORIZON
        assert info["episode"]["r"] == pytest.approx(total[i], abs=1e-4)
    assert venv.env_is_wrapped(VecMonitor) == [False] * 3
    again = EnvpoolVecEnv("CarRacing-v3", 3, HORIZON, seed=4)
    np.testing.assert_array_equal(again.reset(), EnvpoolVecEnv("CarRacing-v3", 3, HORIZON, seed=4).reset())
    assert not np.array_equal(again.reset()[0], EnvpoolVecEnv("CarRacing-v3", 3, HORIZON, seed=5).reset()[0])


def test_test_episode_j_runs_on_the_same_track_whatever_the_wave(runs_dir: Path) -> None:
    """Evaluation episode j is seeded ``seed + j``: the same start whatever the number of envs."""
    cfg = compose_preset("carracing_ppo", runs_dir, "env.backend=envpool").env
    act = lambda obs: np.tile([0.1, 0.5, 0.0], (len(obs), 1))  # noqa: E731
    three = run_episodes(make_vec_env(cfg, 3, seed=0), act, 3, seed=100, max_steps=20)
    two = run_episodes(make_vec_env(cfg, 2, seed=7), act, 3, seed=100, max_steps=20)
    assert three.returns == pytest.approx(two.returns)
    assert len(set(np.round(three.returns, 4))) > 1, "episodes on different tracks"


def test_random_policy_data_is_determined_by_its_seed(runs_dir: Path) -> None:
    cfg = compose_preset("carracing_data", runs_dir, "env.backend=envpool").env
    a, b = (collect_random_policy(cfg, episodes=3, max_steps=8, seed=3, progress=False) for _ in range(2))
    assert a["observations"].shape == (3 * 9, 3, 96, 96) and a["observations"].dtype == np.uint8
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    assert a["truncated"].sum() == 3


@pytest.mark.parametrize(("profile", "backend"), [("smoke", "gymnasium"), ("quick", "envpool"), ("paper", "envpool")])
def test_each_profile_chooses_its_carracing_backend(runs_dir: Path, profile: str, backend: str) -> None:
    """CI's smoke profile stays on the paper's engine; quick and paper use envpool
    (docs/configuration.md, "Env backends"); the command line still wins."""
    assert compose_preset("carracing_ppo", runs_dir, f"budget={profile}").env.backend == backend
    chosen = compose_preset("carracing_ppo", runs_dir, f"budget={profile}", "env.backend=gymnasium")
    assert chosen.env.backend == "gymnasium"
    assert compose_preset("mountaincar_ppo", runs_dir, f"budget={profile}").env.backend == "gymnasium"


def test_backend_separates_hashes_keys_and_run_dirs(runs_dir: Path) -> None:
    gym_cfg = compose_preset("carracing_data", runs_dir)
    pool_cfg = compose_preset("carracing_data", runs_dir, "env.backend=envpool")
    assert config_hash(gym_cfg) != config_hash(pool_cfg)
    assert dataset_key(gym_cfg) != dataset_key(pool_cfg)
    assert "backend" not in dataset_key(gym_cfg)["env"], "old artifacts keep their keys"
    threads = compose_preset("carracing_data", runs_dir, "env.backend=envpool", "env.backend_threads=2")
    assert dataset_key(threads) == dataset_key(pool_cfg), "threads change speed, not data"
    assert config_hash(threads) == config_hash(pool_cfg)
    assert variant_name("auto", "", "envpool") == "env.backend=envpool"
    assert variant_name("auto", "env.backend=envpool", "envpool") == "env.backend=envpool"
    assert variant_name("auto", "seed=1", "gymnasium") == "seed=1"


@pytest.mark.slow
def test_backend_validation_at_small_size(runs_dir: Path, tmp_path: Path) -> None:
    """The validation report end to end: 3 tracks per backend, a smoke V_s trained on envpool
    frames for the cross-reconstruction; the report's numbers agree with its per-episode data."""
    import json

    from plls_bench.repr.store import ensure_representations
    from plls_bench.validation import backends as backend_validation

    ensure_representations(compose_preset("carracing_vs", runs_dir, "env.backend=envpool"))
    out = tmp_path / "analysis"
    backend_validation.main(["--episodes", "3", "--steps", "30", "--budget", "smoke", "--runs", str(runs_dir),
                             "--out", str(out)])
    report = json.loads((out / "backend_validation.json").read_text())
    for backend in backend_validation.BACKENDS:
        returns = report["summary"]["per_episode_returns"][backend]
        assert len(returns) == 3
        assert report["summary"]["returns"][backend]["mean"] == pytest.approx(np.mean(returns))
        assert report["summary"]["lengths"][backend]["mean"] == 30
    rec = report["reconstruction"]
    assert rec["trained_on"] == "envpool" and set(rec["mse"]) == {"gymnasium", "envpool"}
    assert rec["ratio_other_to_own"] == pytest.approx(rec["mse"]["gymnasium"] / rec["mse"]["envpool"])
    assert "V_s trained on envpool frames" in (out / "backend_validation.md").read_text()


def test_two_sample_statistics_match_scipy() -> None:
    from scipy import stats

    from plls_bench.validation.backends import mean_ci, two_sample

    rng = np.random.default_rng(1)
    a, b = rng.normal(0, 1, 40), rng.normal(0.8, 2, 35)
    m = mean_ci(a)
    low, high = stats.t.interval(0.95, len(a) - 1, loc=a.mean(), scale=stats.sem(a))
    assert (m["ci_low"], m["ci_high"]) == pytest.approx((low, high))
    t = two_sample(a, b)
    assert t["diff"] == pytest.approx(b.mean() - a.mean())
    assert t["welch_p"] == pytest.approx(stats.ttest_ind(b, a, equal_var=False).pvalue)
    assert t["diff_ci_low"] < t["diff"] < t["diff_ci_high"]
    assert two_sample(np.full(5, 1000.0), np.full(5, 1000.0))["welch_p"] == 1.0


def test_collector_reads_a_profiles_envpool_runs_as_the_presets_runs(tmp_path: Path) -> None:
    """A profile that runs CarRacing on envpool writes ``<experiment>/env.backend=envpool/``; the
    collector reads those as the preset's runs, and a smoke run in ``default`` does not displace them."""
    import shutil

    from plls_bench.report.evidence.load import Runs
    from tests.synthetic_runs import finish, make_run, write_repr

    runs = tmp_path / "runs"
    for seed in (0, 1):
        run, cfg = make_run(runs, "carracing_va", seed, "quick")
        write_repr(run, "action", 3, 0.001, f"model{seed}")
        finish(run, cfg)
    shutil.move(str(runs / "carracing_va" / "default"), str(runs / "carracing_va" / "env.backend=envpool"))
    run, cfg = make_run(runs, "carracing_va", 0, "smoke")
    write_repr(run, "action", 1, 0.5, "smoke")
    finish(run, cfg)
    exp = Runs(runs).experiment("carracing_va")
    assert [(t.seed, t.cfg("budget.name"), t.path.parent.name) for t in exp.trials] == [
        (0, "quick", "env.backend=envpool"), (1, "quick", "env.backend=envpool")]
