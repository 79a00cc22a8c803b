"""The evaluation-modes table (plls_bench/report/tables/eval_modes.py), on hand-built runs: each PPO
arm's finals acting on the mean and sampling actions, paired per trial and tested two-sided from
5 trials, the p checked against scipy; the N_e sweep's other values as rows of their own."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from plls_bench.report import render_all
from tests.synthetic_runs import finish, make_run, write_eval

ITERATIONS = [0, 16, 32, 48, 64]


def arm(runs: Path, experiment: str, seeds: int, mean_return, sampled_offset, override: str | None = None) -> None:
    """``seeds`` finished trials (of the variant ``override`` names, if any); the mean-action return
    ``mean_return(seed, i)`` at each evaluation, sampled actions ``sampled_offset(seed)`` more."""
    extra, variant = ((override,), override) if override else ((), "default")
    for seed in range(seeds):
        run, cfg = make_run(runs, experiment, seed, "quick", f"budget.trials={seeds}", *extra, variant=variant)
        write_eval(run, cfg, ITERATIONS, [[mean_return(seed, i)] * 2 for i in ITERATIONS], sampled_offset(seed))
        finish(run, cfg)


def test_each_arm_s_two_readings_are_paired_and_tested(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    arm(runs, "carracing_ppo", 5, lambda seed, i: 2.0 * i + seed, lambda seed: 300.0 + 7 * seed)
    arm(runs, "carracing_plls_ppo", 5, lambda seed, i: 100.0 + seed, lambda seed: (-1.0) ** seed)
    arm(runs, "carracing_ppo_vs", 3, lambda seed, i: -50.0, lambda seed: 10.0)
    arm(runs, "carracing_plls_ppo", 5, lambda seed, i: -5.0, lambda seed: 200.0 + seed, "repr.action.latent_dim=16")
    render_all(runs, tmp_path / "out", only=["eval_modes"])
    table = pd.read_csv(tmp_path / "out" / "tables" / "eval_modes.csv").set_index("experiment")
    by_variant = pd.read_csv(tmp_path / "out" / "tables" / "eval_modes.csv").set_index(["experiment", "variant"])
    table = table[table["variant"] == "default"]

    ppo = table.loc["carracing_ppo"]
    # final = mean of the last 3 evaluations (iterations 32, 48, 64): 2 * 48 + seed, over seeds 0-4
    assert ppo["final_mean_action"] == pytest.approx(98.0) and ppo["final_sampled"] == pytest.approx(98.0 + 314.0)
    assert ppo["p"] == pytest.approx(stats.ttest_1samp(300.0 + 7 * np.arange(5), 0).pvalue)
    assert (ppo["trials"], ppo["readings"], ppo["exploration"]) == (5, "sampled higher", "Gaussian")

    plls = table.loc["carracing_plls_ppo"]  # +1, -1, +1, -1, +1: mean 0.2, no difference
    assert plls["p"] == pytest.approx(stats.ttest_1samp([1, -1, 1, -1, 1], 0).pvalue)
    assert plls["readings"] == "no difference found"

    assert table.loc["carracing_ppo_vs", "readings"] == "not tested"  # 3 trials: below the protocol's 5
    unrun = table.loc["carracing_ppo_va"]
    assert (unrun["trials"], unrun["readings"], unrun["exploration"]) == (0, "not run", "—")
    text = (tmp_path / "out" / "tables" / "eval_modes.md").read_text()
    assert "not tested: needs 5 trials, has 3" in text and "paired t = " in text

    # conf/sweep/ne.yaml: every value but the preset's 32 is a row, read from its own variant's runs
    sweep = by_variant.loc["carracing_plls_ppo"]
    assert [v for v in sweep.index if v != "default"] == [f"repr.action.latent_dim={n}" for n in (3, 8, 16, 64)]
    ne16 = sweep.loc["repr.action.latent_dim=16"]
    assert (ne16["trials"], ne16["readings"]) == (5, "sampled higher")
    assert ne16["final_mean_action"] == pytest.approx(-5.0) and ne16["final_sampled"] == pytest.approx(197.0)
    assert ne16["p"] == pytest.approx(stats.ttest_1samp(200.0 + np.arange(5), 0).pvalue)
    assert sweep.loc["repr.action.latent_dim=8", "readings"] == "not run"
    assert "PL-LS + PPO, repr.action.latent_dim=16 (`carracing_plls_ppo`, sweep `ne`)" in text
