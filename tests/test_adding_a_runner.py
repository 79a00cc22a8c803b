"""Adding a runner is one registry entry (and its config checks, the config layer's row): a toy
runner registered for the test goes through the dry run's plan and costs, the bench's rate keys
and measurement lookup, the collector's per-runner lookups and the records' export, with no other
table to extend."""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from bench.throughput import MEASURES
from bench.throughput import rate_keys as bench_rate_keys
from plls_bench.config.runner_checks import RUNNER_CHECKS, validate_ppo
from plls_bench.pipeline import runner_registry as runner_specs
from plls_bench.pipeline.plan import plan_profile
from plls_bench.pipeline.rates import rate_keys
from plls_bench.pipeline.record_export import export_records
from plls_bench.pipeline.runner_registry import RunnerSpec, runner_spec
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.returns import load_curves, x_label
from plls_bench.rundirs.record_layout import PARTIAL_DIR, PARTIAL_MARKER
from plls_bench.train.schedule import Schedule
from tests.synthetic_runs import finish, make_run, write_eval

PRESET, TOY = "mountaincar_ppo", ("runner=toy",)  # a toy runner learning with the preset's PPO section


@pytest.fixture
def toy(monkeypatch: pytest.MonkeyPatch) -> Iterator[RunnerSpec]:
    """A runner that trains a policy, timed like PPO, registered only for the test."""
    spec = RunnerSpec("toy", lambda: lambda cfg, run: None, order=len(runner_specs.SPECS),
                      measure="ppo_iterations", trains_policy=True,
                      iteration_unit="toy iteration ({} envs)", iteration_keys=("algo.ppo.n_envs",),
                      load_policy_files=lambda: lambda run_dir: {"toy/policy.bin": b"weights"},
                      load_resume_files=lambda: _toy_resume_files)
    monkeypatch.setattr(runner_specs, "SPECS", (*runner_specs.SPECS, spec))
    monkeypatch.setitem(runner_specs.RUNNERS, "toy", spec)
    monkeypatch.setitem(RUNNER_CHECKS, "toy", validate_ppo)  # the config layer's row
    yield spec


def _toy_resume_files(run_dir: Path) -> tuple[list[str], int] | None:
    """The toy's checkpoint: one file, at iteration 4, when it has been written."""
    return (["toy/state.bin"], 4) if (run_dir / "toy" / "state.bin").exists() else None


def test_the_dry_run_plans_and_costs_the_toy_runner(toy: RunnerSpec, runs_dir: Path) -> None:
    rates = {f"train/{PRESET}": 1000.0, f"eval/{PRESET}": 5000.0}
    plan = plan_profile("quick", str(runs_dir), only=[PRESET], rates=rates, count_records=False, overrides=TOY)[0]
    assert plan.runner == "toy" and runner_spec(plan.runner) is toy and not plan.missing_rates
    cfg = plan.trials[0].cfg
    assert rate_keys(cfg) == {"train": f"train/{PRESET}", "eval": f"eval/{PRESET}"}
    schedule = Schedule.of(cfg)  # its evaluation schedule: the trainers' one, from its algo section
    evals = schedule.evaluations * cfg.budget.eval_episodes * cfg.env.max_episode_steps
    per_trial = cfg.budget.train_env_steps / 1000.0 + evals / 5000.0
    assert plan.env_steps_per_trial == cfg.budget.train_env_steps
    assert plan.seconds == pytest.approx(len(plan.trials) * per_trial)


def test_the_bench_finds_the_toy_runners_rate_keys_and_measurement(toy: RunnerSpec, runs_dir: Path) -> None:
    cfg = plan_profile("quick", str(runs_dir), only=[PRESET], rates={}, overrides=TOY)[0].trials[0].cfg
    assert bench_rate_keys(cfg) == [f"train/{PRESET}", f"eval/{PRESET}"]
    measurement = MEASURES[toy.measure]  # looked up, never timed here
    assert measurement.kinds == ("train", "eval") and measurement.env_bound


def test_the_collector_reads_the_toy_runners_curves_and_iteration_unit(toy: RunnerSpec, runs_dir: Path) -> None:
    for seed in range(3):  # the quick budget's trials: no gap
        run, cfg = make_run(runs_dir, PRESET, seed, "quick", *TOY)
        write_eval(run, cfg, [0, 5, 10], [[1.0], [2.0], [3.0 + seed]])
        finish(run, cfg)
    runs = Runs(runs_dir)
    exp = runs.experiment(PRESET)
    assert exp.cfg("runner") == "toy"
    assert x_label(exp, "iteration") == f"toy iteration ({cfg.algo.ppo.n_envs} envs)"
    curves = load_curves(runs, exp, "toy")
    assert curves.n == 3 and list(curves.grid) == [0, 5, 10] and not runs.gaps


def test_records_carry_the_toy_runners_policy_and_resume_files(toy: RunnerSpec, runs_dir: Path,
                                                                tmp_path: Path) -> None:
    finished, cfg = make_run(runs_dir, PRESET, 0, "quick", *TOY)
    write_eval(finished, cfg, [0, 5], [[1.0], [2.0]])
    finish(finished, cfg)
    unfinished, _ = make_run(runs_dir, PRESET, 1, "quick", *TOY)
    unfinished.write_bytes("toy/state.bin", b"state")
    records = tmp_path / "records"
    done = export_records(runs_dir, records)
    assert len(done.written) == 1 and len(done.partial) == 1, done.summary()
    finished_key, partial_key = (str(r.path.relative_to(runs_dir)) for r in (finished, unfinished))
    assert (records / finished_key / "toy" / "policy.bin").read_bytes() == b"weights"
    assert (records / PARTIAL_DIR / partial_key / "toy" / "state.bin").read_bytes() == b"state"
    assert (records / PARTIAL_DIR / partial_key / PARTIAL_MARKER).is_file()
