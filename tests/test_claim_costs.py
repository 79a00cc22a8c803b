"""What an undecided comparison row says it would cost to decide (plls_bench/report/claims/costs.py):
each arm from its own count up to the target, at each arm's own rate."""
from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from plls_bench.pipeline.plan import plan_profile
from plls_bench.report.claims import power
from plls_bench.report.claims.claims_table import read_claims
from plls_bench.report.claims.costs import MoreTrials, more_trials, trial_seconds
from plls_bench.report.collect import PAPER_DIR
from plls_bench.report.evidence.claim_settings import ClaimSettings, load_settings
from plls_bench.report.evidence.load import Runs
from plls_bench.rundirs.record_layout import PARTIAL_DIR, PARTIAL_MARKER
from plls_bench.rundirs.run_dir import config_hash
from plls_bench.train.schedule import Schedule
from tests.conftest import REPO_ROOT, compose_preset


def test_each_arm_is_costed_from_its_own_count_at_its_own_rate() -> None:
    more = MoreTrials(target=7, more=(4, 2), per_trial_s=(3600.0, 1800.0))
    assert more.seconds == 4 * 3600 + 2 * 1800
    assert more.text(("a", "b"), "the planned 7") == (
        "to the planned 7 per arm: 4 + 2 more trials, about 5.0 CPU-hours by the dry run's rates "
        "(results/tables/power.md)")


def test_an_arm_without_a_measured_rate_is_named_not_costed() -> None:
    more = MoreTrials(target=5, more=(2, 2), per_trial_s=(3600.0, None))
    assert more.seconds is None
    assert more.text(("a", "b"), "the planned 5") == (
        "to the planned 5 per arm: 2 + 2 more trials (no measured rate for b)")


def test_the_dry_run_s_rates_cost_a_cheap_and_an_expensive_arm_apart() -> None:
    cheap, cnn = trial_seconds("carracing_plls_ppo", "quick"), trial_seconds("carracing_ppo", "quick")
    assert cheap and cnn and cnn > 5 * cheap  # a CNN PPO trial is update-bound on a CPU; the latent arm is not
    more = more_trials("carracing_plls_ppo", "carracing_ppo", "quick", (3, 5), 5)
    assert more.more == (2, 0) and more.seconds == 2 * cheap


def test_a_trial_resuming_near_its_end_does_not_make_more_trials_look_cheap(runs_dir: Path) -> None:
    """Every seed but one resumes from a partial record at 90% of its iterations: one more trial
    still costs a whole trial, as when none resumes."""
    fresh = trial_seconds("mountaincar_ppo", "quick", str(runs_dir))
    cfg = compose_preset("mountaincar_ppo", runs_dir, "budget=quick")
    iterations = Schedule.of(cfg).iterations
    for seed in range(1, cfg.budget.trials):
        marker = runs_dir.parent / "records" / PARTIAL_DIR / "mountaincar_ppo" / "default" / f"seed={seed}"
        marker.mkdir(parents=True)
        payload = {"config_hash": config_hash(replace(cfg, seed=seed)), "iteration": iterations * 9 // 10}
        (marker / PARTIAL_MARKER).write_text(json.dumps(payload))
    trial_seconds.cache_clear()
    plan = plan_profile("quick", str(runs_dir), only=["mountaincar_ppo"], count_records=False)[0]
    assert [t.resumes_at for t in plan.trials][1:] == [iterations * 9 // 10] * (cfg.budget.trials - 1)
    assert fresh and trial_seconds("mountaincar_ppo", "quick", str(runs_dir)) == pytest.approx(fresh)


# Presets the quick profile runs to the plan of every comparison row they are an arm of: the CarRacing
# latent arms (about 1 CPU-hour a trial) and the arms of rows that the presets exist to decide (Fig. 18
# under gSDE, Fig. 21). The rest stop short by cost, and their rows say what the plan would cost:
# the pixel CNN arms (carracing_ppo, carracing_ppo_va, about 20 CPU-hours a trial) and MountainCar past
# the paper's 7 trials (docs/verdicts.md, "One look per row").
RUN_TO_PLAN = ("carracing_plls_ppo", "carracing_ppo_vs", "carracing_plls_ppo_gsde", "carracing_ppo_gsde",
               "cheetah_dbc", "cheetah_plls_dbc")


@pytest.mark.parametrize("preset", RUN_TO_PLAN)
def test_the_quick_and_paper_profiles_run_an_arm_to_its_rows_plans(tmp_path: Path, preset: str) -> None:
    """``reproduce --profile quick|paper`` runs seeds 0 to ``budget.trials`` - 1: fewer than a row's plan
    and the row could only ever be an interim look; more at quick, and trials run that no row reads."""
    rows = read_claims(PAPER_DIR)
    settings = load_settings(PAPER_DIR, [r["claim"] for r in rows])
    arms = {r["claim"]: {r["experiment"], r["baseline"] or r["experiment"]} for r in rows}
    # a row with an arm that stops short by cost is not decided by more trials of this one
    plans = [settings.planned(name) for name, pair in arms.items()
             if preset in pair and pair <= set(RUN_TO_PLAN) and settings.planned(name)]
    assert plans, f"{preset} is an arm of no planned comparison row between presets run to plan"
    assert compose_preset(preset, tmp_path, "budget=quick").budget.trials == max(plans)
    # the paper profile keeps the paper's count where it is larger, never one that leaves a row interim
    assert compose_preset(preset, tmp_path, "budget=paper").budget.trials >= max(plans)


GSDE_ROW = "PL-LS with PPO beats PPO on CarRacing (final return) [gSDE exploration]"


def _gsde_row() -> tuple[ClaimSettings, dict[str, str]]:
    """The declared settings and Fig. 18's gSDE row of ``claims.yaml``."""
    rows = read_claims(PAPER_DIR)
    return load_settings(PAPER_DIR, [r["claim"] for r in rows]), next(r for r in rows if r["claim"] == GSDE_ROW)


def test_a_row_without_runs_prices_its_whole_plan(tmp_path: Path) -> None:
    """The power table costs a row no arm has run yet at the least budget it is judged at."""
    settings, claim = _gsde_row()
    _, record = power._row(Runs(tmp_path / "runs", tmp_path / "records"), claim, settings, settings.family_size)
    per_trial = [trial_seconds(arm, claim["min_budget"]) for arm in (claim["experiment"], claim["baseline"])]
    assert None not in per_trial and "n_a" not in record
    assert record["cost_per_trial_s"] == pytest.approx(sum(per_trial))
    assert record["cost_to_planned_s"] == pytest.approx(settings.planned(claim["claim"]) * sum(per_trial))


def test_a_row_with_one_arm_run_prices_only_the_trials_it_lacks(tmp_path: Path) -> None:
    """Fig. 18's gSDE row with PL-LS + PPO's finished trials and no plain-PPO trial: not judged, and
    its cost counts the PL-LS trials done (a whole plan of both arms would overstate it)."""
    preset = "carracing_plls_ppo_gsde"
    shutil.copytree(REPO_ROOT / "results" / "records" / preset, tmp_path / "records" / preset)
    runs = Runs(tmp_path / "runs", tmp_path / "records")
    done = len(runs.experiment(preset).trials)
    settings, claim = _gsde_row()
    _, record = power._row(runs, claim, settings, settings.family_size)
    plan = settings.planned(claim["claim"])
    per_a, per_b = (trial_seconds(arm, claim["min_budget"]) for arm in (preset, claim["baseline"]))
    assert done > 0 and "n_a" not in record
    assert record["cost_to_planned_s"] == pytest.approx(max(plan - done, 0) * per_a + plan * per_b)


def test_a_seed_past_the_plan_does_not_lower_an_unjudged_rows_cost(tmp_path: Path) -> None:
    """An unjudged row counts only the seeds its plan names: a finished trial at a seed past the plan
    (a trial the row will never read) leaves the cost to the planned n as it was."""
    preset = "carracing_plls_ppo_gsde"
    records = tmp_path / "records" / preset
    shutil.copytree(REPO_ROOT / "results" / "records" / preset, records)
    settings, claim = _gsde_row()

    def cost() -> float:
        _, record = power._row(Runs(tmp_path / "runs", tmp_path / "records"), claim, settings, settings.family_size)
        assert "n_a" not in record
        return record["cost_to_planned_s"]

    before = cost()
    first = sorted(records.glob("*/seed=*"))[0]
    shutil.copytree(first, first.parent / f"seed={settings.planned(claim['claim']) + 3}")
    assert cost() == pytest.approx(before)
