"""The mean-action analysis: the clipped Gaussian's mean against sampling, and the command on a
saved PPO policy (untrained, so its std is SB3's initial exp(0) = 1)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from plls_bench.rundirs.run_dir import Run, config_hash
from plls_bench.validation.mean_action import clipped_gaussian_mean, main
from tests.conftest import compose_preset


@pytest.mark.parametrize("mean,std", [(0.0, 1.0), (1.4, 1.0), (-2.0, 0.5), (0.3, 0.05)])
def test_the_clipped_gaussian_mean_matches_sampling(mean: float, std: float) -> None:
    noise = np.random.default_rng(0).standard_normal(2_000_000)
    sampled = np.clip(mean + std * noise, -1.0, 1.0).mean()
    exact = clipped_gaussian_mean(np.array(mean), np.array(std), np.array(-1.0), np.array(1.0))
    assert abs(float(exact) - sampled) < 2e-3
    if mean == 1.4:  # a mean past the bound: acting on it sends 1, sampling sends 0.77 on average
        assert float(exact) == pytest.approx(0.772, abs=2e-3)


def test_the_command_traces_a_saved_policy(runs_dir: Path, one_torch_thread: None) -> None:
    from plls_bench.train import checkpoint
    from plls_bench.train.ppo_model import build_vec_env, new_model

    cfg = compose_preset("mountaincar_ppo", runs_dir)
    run = Run(runs_dir / "ppo")
    run.prepare(cfg, config_hash(cfg))
    venv = build_vec_env(cfg, 1, seed=0)
    checkpoint.save(run, new_model(cfg, venv), checkpoint.Progress(1, 16, 0.0))
    venv.close()
    assert main([str(run.path), "--steps", "30", "--out", str(runs_dir / "out" / "trace")]) == 0
    [dim] = json.loads((runs_dir / "out" / "trace.json").read_text())["runs"][str(run.path)]
    assert (dim["low"], dim["high"]) == (-1.0, 1.0) and dim["std"] == pytest.approx(1.0)
    # an untrained policy's mean stays near 0: inside the bounds, where clipping changes nothing,
    # and clipping its std-1 samples pulls their mean towards 0
    assert dim["share_below"] == dim["share_above"] == 0.0
    assert dim["deterministic_action"] == pytest.approx(dim["mean"])
    assert 0 < abs(dim["sampled_action"]) < abs(dim["mean"])
    assert "| 0 | [-1, 1] |" in (runs_dir / "out" / "trace.md").read_text()


def test_a_run_dir_without_a_config_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main([str(tmp_path / "nowhere")])
    assert exit_info.value.code == 2 and "runs: no config.json in" in capsys.readouterr().err
    assert not (tmp_path / "results").exists()


def test_run_dirs_may_follow_the_options(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Both run dirs are read as runs (and refused for lacking a config), not the second as an
    unrecognised argument."""
    first, second = tmp_path / "first", tmp_path / "second"
    with pytest.raises(SystemExit) as exit_info:
        main([str(first), "--steps", "5", str(second)])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and f"runs: no config.json in {first}, {second}" in err
