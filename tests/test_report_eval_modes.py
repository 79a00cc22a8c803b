"""The evaluation-modes table (plls_bench/report/tables/eval_modes.py), on hand-built runs: each PPO
arm's finals acting on the mean and sampling actions, paired per trial and tested two-sided from
5 trials, the p checked against scipy."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from plls_bench.report import render_all
from tests.synthetic_runs import finish, make_run, write_eval

ITERATIONS = [0, 16, 32, 48, 64]


def arm(runs: Path, experiment: str, seeds: int, mean_return, sampled_offset) -> None:
    """``seeds`` finished trials; the mean-action return ``mean_return(seed, i)`` at each evaluation,
    sampled actions ``sampled_offset(seed)`` more."""
    for seed in range(seeds):
        run, cfg = make_run(runs, experiment, seed, "quick", f"budget.trials={seeds}")
        write_eval(run, cfg, ITERATIONS, [[mean_return(seed, i)] * 2 for i in ITERATIONS], sampled_offset(seed))
        finish(run, cfg)


def test_each_arm_s_two_readings_are_paired_and_tested(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    arm(runs, "carracing_ppo", 5, lambda seed, i: 2.0 * i + seed, lambda seed: 300.0 + 7 * seed)
    arm(runs, "carracing_plls_ppo", 5, lambda seed, i: 100.0 + seed, lambda seed: (-1.0) ** seed)
    arm(runs, "carracing_ppo_vs", 3, lambda seed, i: -50.0, lambda seed: 10.0)
    render_all(runs, tmp_path / "out", only=["eval_modes"])
    table = pd.read_csv(tmp_path / "out" / "tables" / "eval_modes.csv").set_index("experiment")

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
