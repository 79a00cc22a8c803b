"""The results collector on synthetic run directories: numbers checked against values computed by
hand, broken inputs reported (never a crash, never a write under the runs dir), every registry id
rendered (the CLI: tests/test_report_cli.py)."""
from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from plls_bench.report import BY_ID, ENTRIES, render_all
from plls_bench.report.claims.claims_table import verdict
from plls_bench.report.claims.costs import more_trials
from plls_bench.report.collect import PAPER_DIR, png_size, verify_outputs
from plls_bench.report.evidence.entry_types import Options
from plls_bench.report.evidence.load import Runs
from plls_bench.report.figures.plot import DPI, TITLE_CHARS_PER_INCH, new_figure, suptitle
from tests.conftest import REPO_ROOT
from tests.synthetic_runs import ITERATIONS, build_all, build_hand_runs, finish, make_run, write_eval, write_npz


def tree_state(root: Path) -> dict[str, tuple]:
    """Every path under ``root`` with its bytes' digest, size and mtime (files) or 'dir'."""
    state = {}
    for path in sorted(root.rglob("*")):
        rel = str(path.relative_to(root))
        if path.is_dir():
            state[rel] = ("dir",)
        else:
            stat = path.stat()
            state[rel] = (hashlib.sha256(path.read_bytes()).hexdigest(), stat.st_size, stat.st_mtime_ns)
    return state


@pytest.fixture(scope="module")
def hand(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    root = tmp_path_factory.mktemp("hand")
    build_hand_runs(root / "runs")
    statuses = render_all(root / "runs", root / "out", only=["table3", "fig18", "claims"])
    return root / "out", statuses


def test_curves_on_every_x_axis(hand, tmp_path: Path) -> None:
    runs = hand[0].parent / "runs"
    for axis, per_iteration in (("env_steps", 16 * 1000), ("env_steps_per_env", 1000)):  # Table 2: 16 envs x 1000
        render_all(runs, tmp_path / axis, only=["fig18"], x_axis=axis)
        data = pd.read_csv(tmp_path / axis / "figures" / "fig18.csv")
        assert sorted(set(data["x"])) == [i * per_iteration for i in ITERATIONS] and (data["x_axis"] == axis).all()
    render_all(runs, tmp_path / "wall", only=["fig18"], x_axis="wall_s")  # evaluations at 1.5 s per iteration
    data = pd.read_csv(tmp_path / "wall" / "figures" / "fig18.csv")
    plls = data[data["series"] == "PL-LS + PPO"]
    assert plls["x"].iloc[-1] == 33.0 and (plls["n"] == 3).all()
    assert plls["mean"].iloc[-1] == 100.0
    assert np.interp(3.0, plls["x"], plls["mean"]) == pytest.approx(50, abs=5)  # iteration 2


def test_table3_numbers_match_hand_computation(hand) -> None:
    out, statuses = hand
    table = pd.read_csv(out / "tables" / "table3.csv").set_index("experiment")
    plls, ppo = table.loc["carracing_plls_ppo"], table.loc["carracing_ppo"]
    assert (plls["total_parameters"], plls["trainable_parameters"]) == (8802, 4394)
    assert (ppo["total_parameters"], ppo["trainable_parameters"]) == (3_289_768, 1_644_878)
    assert (plls["paper_total_parameters"], plls["paper_sampled_frequency"]) == (8710, 3750)
    # Mean curve 0, 50, 90, 100, ...: smoothed (trailing 5) 88 at evaluation 5, 98 at 6 -> converged at
    # evaluation 6 = iteration 12 = 12 x 16 envs x 1000 steps. Resampling the three trials: a resample
    # converges at evaluation 5 (iteration 10) only if its evaluations 1 and 2 sum to 175 or more, i.e.
    # it drew seed 1 three times (probability 1/27 = 3.7% > 2.5%), else at 6: CI [10, 12].
    assert plls[["converged_iteration", "converged_iteration_ci_low", "converged_iteration_ci_high"]].tolist() == [
        12, 10, 12]
    assert plls["converged_env_steps"] == 192_000 and plls["converged_env_steps_ci_low"] == 160_000
    assert plls["converged_env_steps_per_env"] == 12_000  # the paper's "iterations" (vector-env steps)
    assert plls["converged_sampled_frequency"] == 12_000 / 16
    assert plls["paper_iterations_to_convergence"] == "60000"
    # PPO rises by 5 per evaluation to the end: never within 5% for 5 evaluations
    assert math.isinf(ppo["converged_iteration"]) and math.isinf(ppo["converged_iteration_ci_low"])
    assert "not converged by 22" in (out / "tables" / "table3.md").read_text()
    assert statuses["table3"].status == "ok"


def test_figure_data_mean_std_and_ci_match_hand_computation(hand) -> None:
    out, _ = hand
    data = pd.read_csv(out / "figures" / "fig18.csv")
    plls = data[data["series"] == "PL-LS + PPO"].set_index("x")
    ppo = data[data["series"] == "PPO"].set_index("x")
    # iteration 2: PL-LS trials returned 20, 80 and 50. A resample's mean is the lowest (highest) value
    # only if it drew that trial three times, probability 1/27 = 3.7% > 2.5%: the CI is their range.
    assert plls.loc[2.0, ["n", "mean", "ci_low", "ci_high"]].tolist() == [3, 50, 20, 80]
    assert plls.loc[2.0, "std"] == pytest.approx(30)
    assert plls.loc[0.0, ["mean", "std", "ci_low", "ci_high"]].tolist() == [0, 0, 0, 0]
    assert ppo.loc[4.0, ["mean", "ci_low", "ci_high"]].tolist() == [20, 10, 30]
    assert len(plls) == len(ppo) == 12 and (data["x_axis"] == "iteration").all()


def claim(out: Path, text: str) -> pd.Series:
    claims = pd.read_csv(out / "tables" / "claims.csv")
    return claims[claims["claim"].str.startswith(text)].iloc[0]


def test_claims_table_matches_hand_computation(hand) -> None:
    out, _ = hand
    assert claim(out, "PL-LS with PPO: total parameters")["verdict"] == "not reproduced"  # 8802 vs 8710
    assert claim(out, "PPO: total parameters")["verdict"] == "reproduced"
    converged = claim(out, "PL-LS with PPO converged by 60,000")  # in env steps per env, as Table 3
    # the runs stop at 22 iterations x 1000 steps per env, and the detector needs 5 evaluations (every
    # 2,000) after a convergence point: it sees one no later than 14,000, far short of the claim's 60,000
    assert converged["verdict"] == "not run at this budget"
    assert converged["reason"].startswith("the detector sees convergence only up to 14,000 at this budget")
    never = claim(out, "PPO not converged by 120,000")  # PPO's lines rise 5 per evaluation: never converged
    assert never["verdict"] == "not run at this budget" and never["reason"].startswith(
        "needs 6 trials for a 95% interval of the median convergence point; has 3 (per trial never, never, never")
    beats = claim(out, "PL-LS with PPO beats PPO on CarRacing")  # 3 + 3 trials: described, not tested
    fig18 = ("carracing_plls_ppo", "carracing_ppo")  # planned 8 per arm (claims.yaml): 5 + 5 more, costed
    cost = more_trials(*fig18, "quick", (3, 3), 8).text(fig18, "the planned 8")
    assert (beats["verdict"], beats["reason"]) == ("not run at this budget", f"needs 5 per arm, has 3 + 3; {cost}")
    assert cost.startswith("to the planned 8 per arm: 5 + 5 more trials, about ") and "CPU-hours" in cost
    assert beats["budget"] == "quick (3 + 3 trials), at 352,000 env steps (iteration 22)"
    # final = mean of the last 3 evaluations: PL-LS 100; PPO 5i + offset at i = 9, 10, 11, offsets 0, 10, 20
    assert beats["suite"].startswith("100 vs 60 (final, mean of the last 3 evaluations); not tested")
    assert "single last evaluation 100 vs 65" in beats["suite"] and "rliable P(A > B) = 1 [1, 1]" in beats["suite"]
    assert beats["suite_value"] == 40 and pd.isna(beats["p"])
    # spread of each trial's mean return over the curve: PPO 27.5, 37.5, 47.5 (std 10); PL-LS
    # (0 + 20 + 80 + 900) / 12, (0 + 80 + 100 + 900) / 12, (0 + 50 + 90 + 900) / 12 (std 10 / 3)
    variance = claim(out, "PPO has the larger variance")
    assert variance["suite_value"] == pytest.approx(10 - 10 / 3)
    cost = more_trials(*fig18, "quick", (3, 3), 10).text(fig18, "the planned 10")
    assert (variance["verdict"], variance["reason"]) == (
        "not run at this budget", f"needs 5 per arm, has 3 + 3; {cost}")
    mse = claim(out, "V_a test MSE on MountainCar")  # models a (0.010, two trials), b (0.014) and c (0.018)
    # mean 0.014, SD 0.004: the t-interval is 0.014 ± t(0.975, 2) 0.004 / sqrt(3), past the 0.0194 threshold
    # (the percentile bootstrap at 3 models was their range, [0.010, 0.018], and read "reproduced")
    half = stats.t.ppf(0.975, 2) * 0.004 / math.sqrt(3)
    assert (mse["suite_value"], mse["ci_low"], mse["ci_high"]) == pytest.approx((0.014, 0.014 - half, 0.014 + half))
    assert mse["verdict"] == "inconclusive" and "3 models" in mse["suite"]
    assert claim(out, "Learned MountainCar policy")["verdict"] == "reproduced"  # 70 steps <= 85
    assert claim(out, "PL-LS with DBC obtains")["verdict"] == "not run at this budget"


@pytest.mark.parametrize(("rule", "low", "high", "expected"), [
    ("at_most", 1, 2, "reproduced"), ("at_most", 3, 4, "not reproduced"), ("at_most", 1, 4, "inconclusive"),
    ("at_least", 2, 4, "reproduced"), ("at_least", 0, 1, "not reproduced"), ("at_least", 1, 3, "inconclusive"),
    ("greater_than", 2.5, 3, "reproduced"), ("greater_than", 1, 2, "not reproduced"),
    ("greater_than", 2, 3, "inconclusive"), ("equal", 2, 2, "reproduced"), ("equal", 3, 3, "not reproduced"),
    ("between", 2, 3, "reproduced"), ("between", 5, 6, "not reproduced"), ("between", 1, 3, "inconclusive"),
    ("at_least", math.inf, math.inf, "reproduced"), ("at_most", 1, math.inf, "inconclusive")])
def test_verdicts_read_the_interval_against_the_threshold(rule: str, low: float, high: float,
                                                         expected: str) -> None:
    assert verdict(rule, low, high, threshold=2.0, threshold_high=4.0) == expected


def test_smoke_budget_claims_are_not_judged(tmp_path: Path) -> None:
    build_hand_runs(tmp_path / "runs", budget="smoke")
    render_all(tmp_path / "runs", tmp_path / "out", only=["claims"])
    assert claim(tmp_path / "out", "PL-LS with PPO beats PPO on CarRacing")["verdict"] == "not run at this budget"
    assert claim(tmp_path / "out", "PPO: total parameters")["verdict"] == "reproduced"  # counts: any budget


def break_runs(runs: Path) -> None:
    """Every kind of damage the collector must survive and report."""
    (runs / "carracing_plls_ppo" / "default" / "seed=3").mkdir()  # an empty run dir
    (runs / "carracing_plls_ppo" / "default" / "seed=1" / "status.json").unlink()
    eval_path = runs / "carracing_ppo" / "default" / "seed=1" / "metrics" / "eval.jsonl"
    text = eval_path.read_text()
    eval_path.write_text(text[: len(text) - len(text.splitlines()[-1]) // 2 - 1])  # killed mid-line
    # seeds 1 and 2 missing; this one failed after 3 evaluations
    run, cfg = make_run(runs, "cheetah_dbc", 0, "quick", "budget.trials=3")
    write_eval(run, cfg, [0, 1000, 2000], [[1.0], [2.0], [3.0]])
    with open(run.metrics_path("eval"), "a") as handle:
        handle.write("not json\n")
    finish(run, cfg, "failed")
    run, cfg = make_run(runs, "carracing_va", 0)
    run.write_bytes("samples/action_reconstructions.npz", b"PK\x03\x04 not a zip")
    finish(run, cfg)
    run, cfg = make_run(runs, "carracing_vs", 0)  # no frame with the car on the grass
    frames = np.zeros((1, 3, 96, 96), dtype=np.uint8)
    write_npz(run, "samples/state_reconstructions.npz", originals=frames, reconstructions=frames,
              labels=np.array(["road"]))
    finish(run, cfg)


def test_broken_runs_are_reported_never_crash_and_never_written(tmp_path: Path) -> None:
    runs, out = tmp_path / "runs", tmp_path / "out"
    build_hand_runs(runs)
    break_runs(runs)
    before = tree_state(runs)
    statuses = render_all(runs, out)
    assert tree_state(runs) == before, "the collector must not write, touch or delete anything under runs/"
    assert not [s.id for s in statuses.values() if s.status == "error"], [s.error for s in statuses.values()]
    readme = (out / "README.md").read_text()
    render_all(runs, tmp_path / "again")  # the same runs give the same file, whenever it is made
    assert (tmp_path / "again" / "README.md").read_text().replace("again", "out") == readme.replace("again", "out")
    assert "- Collector: `" in readme and "- Newest evidence: 20" in readme
    for gap in ("carracing_plls_ppo/default seed=3: empty run dir",
                "carracing_plls_ppo/default seed=1: status.json missing or unreadable",
                "carracing_ppo/default seed=1: metrics/eval.jsonl: truncated last line skipped",
                "carracing_ppo/default seed=1: curve ends before the method's last evaluation: comparisons "
                "are judged where every trial reaches",
                "cheetah_dbc/default: seed(s) 1, 2 missing (budget.trials=3)",
                "cheetah_dbc/default seed=0: status failed (RuntimeError: boom)",
                "cheetah_dbc/default seed=0: metrics/eval.jsonl: 1 corrupt line(s) skipped",
                "carracing_va/default seed=0: samples/action_reconstructions.npz missing or unreadable",
                "carracing_vs/default seed=0: samples/state_reconstructions.npz: no frame labelled grass",
                "carracing_ppo_vs/default: no runs"):
        assert gap in readme, gap
    assert statuses["fig18"].status == "partial" and statuses["fig18"].trials == {"PL-LS + PPO": 3, "PPO": 3}
    assert statuses["fig21"].trials == {"PL-LS + DBC": 0, "DBC": 1} and statuses["fig16"].status == "empty"
    last = pd.read_csv(out / "figures" / "fig18.csv").groupby("series").last()
    assert last.loc["PPO", "n"] == 2  # the truncated trial lost its last evaluation
    fig = BY_ID["fig18"].build(Runs(runs), BY_ID["fig18"], Options("iteration", PAPER_DIR)).figure
    assert "PL-LS + PPO: 3 trials, PPO: 3 trials" in fig.get_suptitle()


@pytest.mark.slow
def test_every_registry_id_renders_from_synthetic_runs(tmp_path: Path) -> None:
    runs, out = tmp_path / "runs", tmp_path / "out"
    build_all(runs)
    statuses = render_all(runs, out)
    assert list(statuses) == [e.id for e in ENTRIES]
    assert {i: (s.status, s.gaps, s.error) for i, s in statuses.items() if s.status != "ok"} == {}
    assert verify_outputs(out, statuses) == []
    readme = (out / "README.md").read_text()
    for entry in ENTRIES:
        if entry.kind == "figure":
            assert png_size(out / "figures" / f"{entry.id}.png") == (entry.size[0] * DPI, entry.size[1] * DPI)
            assert len(pd.read_csv(out / "figures" / f"{entry.id}.csv")) > 0
            assert f"](figures/{entry.id}.png)" in readme
        else:
            assert (out / "tables" / f"{entry.id}.md").read_text().strip() in readme
            assert r"\begin{tabular}" in (out / "tables" / f"{entry.id}.tex").read_text()
    assert "Budget profile: **quick**" in readme


def test_output_check_catches_a_wrong_size_and_a_blank_image(tmp_path: Path) -> None:
    from plls_bench.report.figures.plot import save_figure

    (tmp_path / "runs").mkdir()
    statuses = render_all(tmp_path / "runs", tmp_path / "out", only=["fig18", "fig21"])  # no runs: placeholders
    assert verify_outputs(tmp_path / "out", statuses) == []
    save_figure(new_figure((3.0, 2.0)), tmp_path / "out" / "figures" / "fig18")  # blank, and too small
    fig = new_figure(BY_ID["fig21"].size)
    save_figure(fig, tmp_path / "out" / "figures" / "fig21")  # right size, blank
    assert verify_outputs(tmp_path / "out", statuses) == ["fig18: fig18.png missing or not 700x450 pixels",
                                                           "fig21: fig21.png is blank"]


def test_a_long_figure_title_is_wrapped_to_the_figure_width_not_clipped() -> None:
    fig = new_figure((4.0, 3.0))
    suptitle(fig, "Fig. 10", "MountainCar, average return (SB3 Gaussian exploration, the literal reading) "
             "(budget paper)", {"PL-LS + PPO": 3, "PPO": 3})
    lines = fig.get_suptitle().split("\n")
    assert len(lines) >= 3 and max(map(len, lines)) <= 4 * TITLE_CHARS_PER_INCH
    assert " ".join(lines).startswith("Fig. 10 (suite): MountainCar, average return (SB3 Gaussian")


def test_the_random_policy_threshold_is_the_committed_measurement() -> None:
    """claims.csv's "PPO beats the random policy" row copies a measured number: the upper end of the
    random policy's 95% CI on envpool in results/analysis/backend_validation.json (and the paper
    column quotes its mean and CI). Re-measuring the random policy must move the row with it."""
    measured = json.loads((REPO_ROOT / "results" / "analysis" / "backend_validation.json").read_text())
    returns = measured["summary"]["returns"]["envpool"]
    claims = pd.read_csv(PAPER_DIR / "claims.csv")
    row = claims[claims["claim"].str.contains("beats the random policy")].iloc[0]
    assert row["threshold"] == round(returns["ci_high"], 1)
    quoted = f"{returns['mean']:.1f} [{returns['ci_low']:.1f}, {returns['ci_high']:.1f}]"
    assert quoted in row["paper"] and quoted in row["source"]
