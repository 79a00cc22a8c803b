"""The N_e sweep (conf/sweep/ne.yaml): its plan and cost, the collector's arms, the claims row
"N_e = 32 performs the best" and the sweep figure, on hand-built runs and (slow) on a real
two-value smoke sweep."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from plls_bench.config import ConfigError
from plls_bench.pipeline.plan import plan_sweep
from plls_bench.pipeline.sweeps import load_sweep
from plls_bench.report import render_all
from plls_bench.report.claims.claims_table import read_claims
from plls_bench.report.claims.sweep import sweep_best
from plls_bench.report.collect import PAPER_DIR
from plls_bench.report.evidence.claim_settings import load_settings
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.matched import NotJudged
from tests.conftest import REPO_ROOT
from tests.synthetic_runs import finish, make_run, set_starts, write_eval, write_repr

CLAIM = "N_e = 32 performs the best"
PRESET = "carracing_plls_ppo"


def test_the_ne_sweep_is_declared_once_with_the_presets_own_value() -> None:
    sweep = load_sweep("ne")
    assert (sweep.preset, sweep.key, sweep.base) == (PRESET, "repr.action.latent_dim", 32)
    assert sweep.others == (3, 8, 16, 64) and sweep.arm_variant(32) is None
    assert sweep.arm_variant(8) == "repr.action.latent_dim=8"
    with pytest.raises(ConfigError, match="--sweep: unknown sweep 'nope'"):
        load_sweep("nope")


def test_plan_gives_each_value_its_variant_and_its_own_va(tmp_path: Path) -> None:
    plans = plan_sweep(load_sweep("ne"), "quick", str(tmp_path), rates={})
    assert [p.overrides for p in plans] == [(), *[(f"repr.action.latent_dim={v}", "budget.trials=10")
                                                  for v in (3, 8, 16, 64)]]  # conf/sweep/ne.yaml: trials 10
    dirs = [p.trials[0].run_dir.relative_to(tmp_path).parent.as_posix() for p in plans]
    assert dirs[0] == f"{PRESET}/env.backend=envpool"  # quick runs CarRacing on envpool
    assert dirs[2] == f"{PRESET}/repr.action.latent_dim=8,env.backend=envpool"
    assert [len(p.trials) for p in plans] == [11] + [10] * 4, "the preset's own 11; 10 per other value (the row's plan)"
    # each value trains its own V_a: five distinct rate-free workloads name repr_action once per value
    keys = {f"{p.label}": p.missing_rates for p in plans}
    assert all("repr_action/carracing" in missing for missing in keys.values()), keys


def arm(runs: Path, value: int, finals: list[float], mse: float, trials: int = 5, sampled: float = -1.0,
        last_jump: float = 0.0) -> None:
    """``trials`` finished runs of the N_e = ``value`` arm (the preset's own runs for 32), flat
    at -20 until iteration 2 then at ``finals[seed]`` (the last 3 evaluations, the claims' final
    return), the last one ``last_jump`` higher, sampled actions ``sampled`` more; V_a's test MSE ``mse``."""
    variant = "default" if value == 32 else f"repr.action.latent_dim={value}"
    overrides = () if value == 32 else (f"repr.action.latent_dim={value}",)
    for seed in range(trials):
        run, cfg = make_run(runs, PRESET, seed, "quick", f"budget.trials={trials}", *overrides, variant=variant)
        iterations = [0, 2, 4, 6, 8]
        returns = [-20.0 if i <= 2 else finals[seed] + (last_jump if i == iterations[-1] else 0.0) for i in iterations]
        write_eval(run, cfg, iterations, [[r] * 2 for r in returns], sampled)
        write_repr(run, "action", 2, mse, artifact=f"va-{value}")
        finish(run, cfg)


def claim_row(runs: Path, out: Path) -> pd.Series:
    render_all(runs, out, only=["claims"])
    table = pd.read_csv(out / "tables" / "claims.csv").set_index("claim")
    return table[table.index.str.startswith(CLAIM)].iloc[0]


def test_claim_reproduced_when_32_beats_every_other_value(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    for value, level in ((3, 0.0), (8, 10.0), (16, 20.0), (32, 100.0), (64, 30.0)):  # 10 each: the planned n
        arm(runs, value, [level + k for k in range(10)], mse=0.001 * value, trials=10)
    for seed in range(10):  # N_e = 8's trials ran on two commits and devices
        run_dir = runs / PRESET / "repr.action.latent_dim=8" / f"seed={seed}"
        set_starts(run_dir, ("cpu", "a" * 40) if seed < 2 else ("cuda:0", "b" * 40))
    row = claim_row(runs, tmp_path / "out")
    # every other value loses in every one of 10,000 random splits of its 10 + 10 trials: p = 1 / 10,001,
    # Holm-corrected over the 16 primary rows claims.yaml declares (the untested ones at p = 1)
    assert row["verdict"] == "reproduced", row["reason"]
    assert row["reason"] == "Holm-adjusted p = 0.0016 over 16 primary comparisons <= 0.05, in the claim's direction"
    assert row["budget"].startswith("quick (10 + 10 + 10 + 10 + 10 trials), at ")
    assert "v=64 104.5 vs 34.5, Welch t = 51.70, p = 0.0001 (the larger of permutation 0.0001" in row["suite"]
    assert "rliable P = 1 [1, 1]" in row["suite"]
    assert row["budget"].endswith("; latent_dim=8 pools seeds 0, 1 (cpu, aaaaaaa); "
                                  "seeds 2, 3, 4, 5, 6, 7, 8, 9 (cuda, bbbbbbb)")
    render_all(runs, tmp_path / "out", only=["sweep_ne"])
    data = pd.read_csv(tmp_path / "out" / "figures" / "sweep_ne.csv")
    final = data.query("panel == 'final' and series == 'acting on the mean'").set_index("value")
    assert final.loc[32, "mean"] == 104.5 and final.loc[8, "variant"] == "repr.action.latent_dim=8"
    mse = data.query("panel == 'va_test_mse' and series == 'z sampled'").set_index("value")
    assert mse["mean"].to_dict() == pytest.approx({v: 0.001 * v for v in (3, 8, 16, 32, 64)})


def test_claim_not_reproduced_when_another_value_beats_32(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    for value, level in ((3, 0.0), (8, 500.0), (16, 20.0), (32, 100.0), (64, 30.0)):
        arm(runs, value, [level + k for k in range(10)], mse=0.01, trials=10)
    row = claim_row(runs, tmp_path / "out")
    assert row["verdict"] == "not reproduced"  # N_e = 8 stands for the row: it beats 32
    assert row["suite_value"] == -400.0 and "v=8 104.5 vs 504.5" in row["suite"] and "v=8" in row["suite"]


def test_sampled_actions_row_reads_the_same_trials_acting_on_sampled_actions(tmp_path: Path) -> None:
    runs = tmp_path / "runs"  # N_e = 32 best acting on the mean; N_e = 3 best (by 300) when actions are sampled
    for value, level, sampled in ((3, 0.0, 400.0), (8, 10.0, 0.0), (16, 20.0, 0.0), (32, 100.0, 0.0), (64, 30.0, 0.0)):
        arm(runs, value, [level + k for k in range(10)], mse=0.01, trials=10, sampled=sampled)
    render_all(runs, tmp_path / "out", only=["claims"])
    table = pd.read_csv(tmp_path / "out" / "tables" / "claims.csv").set_index("claim")
    mean, sampled = (table.loc[f"{CLAIM} (CarRacing, final return{tail})"] for tail in ("", "; sampled actions"))
    assert mean["verdict"] == "reproduced" and "v=3 104.5 vs 4.5" in mean["suite"]
    assert sampled["verdict"] == "not reproduced" and sampled["suite_value"] == pytest.approx(-300.0)
    assert "v=3 104.5 vs 404.5" in sampled["suite"] and "v=8 104.5 vs 14.5" in sampled["suite"]
    render_all(runs, tmp_path / "out", only=["sweep_ne"])  # the figure draws both readings of the same trials
    data = pd.read_csv(tmp_path / "out" / "figures" / "sweep_ne.csv").query("panel == 'final'")
    finals = data.pivot(index="value", columns="series", values="mean")
    assert finals.loc[3].to_dict() == pytest.approx({"acting on the mean": 4.5, "sampled actions": 404.5})
    assert finals.loc[32].to_dict() == pytest.approx({"acting on the mean": 104.5, "sampled actions": 104.5})


def test_figure_final_is_the_claims_final_not_the_last_evaluation(tmp_path: Path) -> None:
    runs = tmp_path / "runs"  # N_e = 8 jumps by 300 at its last evaluation only: the mean of 3 moves by 100
    for value, level, jump in ((3, 0.0, 0.0), (8, 10.0, 300.0), (16, 20.0, 0.0), (32, 100.0, 0.0), (64, 30.0, 0.0)):
        arm(runs, value, [level + k for k in range(10)], mse=0.01, trials=10, last_jump=jump)
    assert "v=8 104.5 vs 114.5" in claim_row(runs, tmp_path / "out")["suite"]
    render_all(runs, tmp_path / "out", only=["sweep_ne"])
    data = pd.read_csv(tmp_path / "out" / "figures" / "sweep_ne.csv").set_index(["panel", "series", "value"])
    assert data.loc[("final", "acting on the mean", 8), "mean"] == pytest.approx(114.5)  # last evaluation: 314.5
    assert data.loc[("mean", "acting on the mean", 8), "mean"] == pytest.approx((-40 + 3 * 14.5 + 300) / 5)


def test_claim_not_run_names_the_missing_values_and_the_trial_count(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    for value in (32, 8):
        arm(runs, value, [1.0, 2.0, 3.0], mse=0.01, trials=3)
    row = claim_row(runs, tmp_path / "out")
    assert row["verdict"] == "not run at this budget"
    assert row["reason"].startswith("no runs of repr.action.latent_dim = 3, 16, 64 (python -m plls_bench.reproduce")
    for value in (3, 16, 64):
        arm(runs, value, [1.0, 2.0, 3.0], mse=0.01, trials=1)
    row = claim_row(runs, tmp_path / "out2")
    assert row["budget"].startswith("quick (1 + 3 + 1 + 3 + 1 trials)")  # in the order 3, 8, 16, 32, 64
    # the hardest untested comparison stands for the row (and plans its trials): N_e = 8 ties with 32,
    # where each one-trial value lies below 32's mean
    assert (row["verdict"], row["reason"]) == ("not run at this budget", "needs 5 per arm, has 3 + 3")


SMOKE = [sys.executable, "-m", "plls_bench", "-m", f"+experiment={PRESET}", "budget=smoke", "progress=false"]


@pytest.mark.slow
def test_two_value_smoke_sweep_end_to_end(tmp_path: Path) -> None:
    """The base preset (N_e = 32) and the override N_e = 8 as multiruns at smoke budget: each lands
    in its own variant with its own V_a, and the collector finds both in the figure's data."""
    runs = tmp_path / "runs"
    for extra in ([], ["repr.action.latent_dim=8"]):
        done = subprocess.run([*SMOKE, f"runs_dir={runs}", "seed=0", *extra], cwd=REPO_ROOT,
                              capture_output=True, text=True, timeout=1800)
        assert done.returncode == 0, done.stderr[-3000:]
    assert (runs / PRESET / "default" / "seed=0" / "metrics" / "repr_test.json").is_file()
    assert (runs / PRESET / "repr.action.latent_dim=8" / "seed=0" / "metrics" / "repr_test.json").is_file()
    assert len([p for p in (runs / "artifacts" / "repr_action").iterdir() if p.is_dir()]) == 2  # V_a per N_e, by key
    out = tmp_path / "out"
    render_all(runs, out, only=["sweep_ne", "claims"], records_dir=None)
    data = pd.read_csv(out / "figures" / "sweep_ne.csv")
    for panel in ("final", "mean", "va_test_mse"):
        assert set(data.query(f"panel == '{panel}'")["value"]) == {8, 32}, panel
    assert set(data.query("panel == 'va_test_mse'")["series"]) == {"z sampled", "decode(mu)"}
    row = claim_row(runs, tmp_path / "out2")
    assert row["verdict"] == "not run at this budget"
    assert row["reason"] == "carracing_plls_ppo ran at budget smoke; judged from budget quick up"
    with pytest.raises(NotJudged, match="no runs of repr.action.latent_dim = 3, 16, 64"):
        sweep_best(Runs(runs), {"param": "ne", "x_axis": "", "claim": CLAIM},
                   load_settings(PAPER_DIR, [r["claim"] for r in read_claims(PAPER_DIR)]))
