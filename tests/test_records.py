"""Committed run records: what is exported, and that the collector regenerates the same tables
from records alone (a fresh clone) and keeps them when a smoke run appears beside them."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from plls_bench.pipeline import record_export as export
from plls_bench.pipeline.record_export import export_records, record_files
from plls_bench.pipeline.record_export import main as records_main
from plls_bench.report.collect import render_all
from plls_bench.report.evidence.load import Runs
from plls_bench.rundirs.record_layout import records_dir_for
from plls_bench.rundirs.run_dir import PARAMS_FILE
from tests.synthetic_runs import build_all, fill, finish, make_run

TABLES = ("claims", "stats", "table3")


def _tables(out: Path) -> dict[str, str]:
    return {name: (out / "tables" / f"{name}.csv").read_text() for name in TABLES}


@pytest.fixture(scope="module")
def quick_runs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("records") / "results"
    build_all(root / "runs", budget="quick")
    return root


def test_records_hold_the_collector_files_and_the_final_checkpoint_only(quick_runs: Path, tmp_path: Path) -> None:
    run_dir = next((quick_runs / "runs" / "mountaincar_ppo" / "default").iterdir())
    (run_dir / "checkpoints" / "ppo-0000001.zip").write_bytes(b"older weights")
    (run_dir / "checkpoints" / "ppo-0000002.zip").write_bytes(b"final weights")
    (run_dir / "checkpoints" / "latest.json").write_text(json.dumps(
        {"model": "ppo-0000002.zip", "normalization": None, "progress": {"iteration": 2}, "rng": {}}))
    (run_dir / "sb3").mkdir(exist_ok=True)
    (run_dir / "sb3" / "progress.csv").write_text("x\n")
    names = {str(p) for p in record_files(run_dir)}
    assert {"config.json", "status.json", "metrics/eval.jsonl", PARAMS_FILE} <= names
    assert not any(n.startswith(("checkpoints", "sb3", ".hydra")) for n in names)

    out = tmp_path / "records"
    first = export_records(quick_runs / "runs", out)
    assert first.written and not first.skipped
    record = out / run_dir.relative_to(quick_runs / "runs")
    assert sorted(p.name for p in (record / "checkpoints").iterdir()) == ["latest.json", "ppo-0000002.zip"]
    assert not list(out.rglob("sb3")) and not list(out.rglob("ppo-0000001.zip")), "only the final checkpoint"
    again = export_records(quick_runs / "runs", out)
    assert again.written == [] and again.unchanged == len(first.written), "an unchanged record is not rewritten"


def test_a_file_over_the_cap_is_left_out_and_reported(quick_runs: Path, tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    run_dir = next((quick_runs / "runs" / "mountaincar_ppo" / "default").iterdir())
    (run_dir / "checkpoints" / "latest.json").write_text(json.dumps(
        {"model": "ppo-0000003.zip", "normalization": None, "progress": {"iteration": 3}, "rng": {}}))
    (run_dir / "checkpoints" / "ppo-0000003.zip").write_bytes(b"w" * 2048)
    monkeypatch.setattr(export, "MAX_FILE_BYTES", 1024)
    done = export_records(quick_runs / "runs", tmp_path / "records")
    key = str(run_dir.relative_to(quick_runs / "runs"))
    assert f"{key}/checkpoints/ppo-0000003.zip: over 0 MiB, not recorded" in done.skipped
    assert not (tmp_path / "records" / key / "checkpoints" / "ppo-0000003.zip").exists()
    assert (tmp_path / "records" / key / "checkpoints" / "latest.json").exists()


def test_smoke_and_unfinished_runs_are_not_recorded(tmp_path: Path) -> None:
    runs = tmp_path / "results" / "runs"
    smoke, cfg = make_run(runs, "mountaincar_ppo", 0, budget="smoke")
    finish(smoke, cfg)
    running, cfg = make_run(runs, "mountaincar_plls_ppo", 0, budget="quick")
    done = export_records(runs)
    assert done.written == [] and any("mountaincar_plls_ppo" in s and "running" in s for s in done.skipped)
    assert not (records_dir_for(runs) / "mountaincar_ppo").exists()
    assert records_main(["--runs", str(runs)]) == 0


@pytest.mark.slow
def test_fresh_clone_regenerates_the_same_tables_from_records(quick_runs: Path, tmp_path: Path) -> None:
    """Tables from the run dirs == tables from the records alone == tables from the records with
    a smoke run of the same preset and seed beside them (it must not erase the evidence)."""
    from_runs = tmp_path / "from_runs"
    render_all(quick_runs / "runs", from_runs, only=list(TABLES))
    clone = tmp_path / "clone" / "results"
    export_records(quick_runs / "runs", clone / "records")
    from_records = tmp_path / "from_records"
    render_all(clone / "runs", from_records, only=list(TABLES), records_dir=clone / "records")
    assert _tables(from_records) == _tables(from_runs)

    smoke, cfg = make_run(clone / "runs", "mountaincar_ppo", 0, budget="smoke")
    fill(smoke, cfg, np.random.default_rng(1))
    finish(smoke, cfg)
    with_smoke = tmp_path / "with_smoke"
    statuses = render_all(clone / "runs", with_smoke, only=list(TABLES), records_dir=clone / "records")
    assert _tables(with_smoke) == _tables(from_runs)
    assert any("config differs" in g for g in statuses["claims"].gaps), "the smoke run is reported, not used"


def test_records_only_ignores_the_runs_dir(quick_runs: Path, tmp_path: Path) -> None:
    """``--records-only``: the tables of the records alone with a smoke run beside them, which is
    neither used nor reported; the README says the runs dir was not read."""
    from plls_bench.report.__main__ import main as report_main

    clone = tmp_path / "results"
    export_records(quick_runs / "runs", clone / "records")
    smoke, cfg = make_run(clone / "runs", "mountaincar_ppo", 0, budget="smoke")
    finish(smoke, cfg)
    from_records, records_only = tmp_path / "from_records", tmp_path / "records_only"
    render_all(None, from_records, only=list(TABLES), records_dir=clone / "records")
    assert report_main(["--runs", str(clone / "runs"), "--records-only", "--out", str(records_only),
                        "--only", *TABLES, "--no-progress"]) == 0
    assert _tables(records_only) == _tables(from_records)
    readme = (records_only / "README.md").read_text()
    assert "Runs dir: not read (`--records-only`)" in readme
    assert str(clone / "runs") not in readme and "config differs" not in readme


def test_a_local_run_replaces_its_record(quick_runs: Path, tmp_path: Path) -> None:
    clone = tmp_path / "results"
    export_records(quick_runs / "runs", clone / "records")
    shutil.copytree(quick_runs / "runs" / "mountaincar_ppo", clone / "runs" / "mountaincar_ppo")
    trials = Runs(clone / "runs", clone / "records").experiment("mountaincar_ppo").trials
    assert [t.source for t in trials] == ["run", "run", "run"] and [t.seed for t in trials] == [0, 1, 2]



def test_a_longer_budget_replaces_the_records_once_it_can_be_judged(quick_runs: Path, tmp_path: Path) -> None:
    """Two finished paper trials beside three recorded quick ones: the quick group is still the
    one judged (two cannot be); the third finished paper trial makes the paper group the one."""
    clone = tmp_path / "results"
    export_records(quick_runs / "runs", clone / "records")
    for seed in range(3):
        run, cfg = make_run(clone / "runs", "mountaincar_ppo", seed, budget="paper")
        finish(run, cfg) if seed < 2 else None
        runs = Runs(clone / "runs", clone / "records")
        exp = runs.experiment("mountaincar_ppo")
        assert (exp.budget, [t.seed for t in exp.trials]) == ("quick", [0, 1, 2])
        assert any("config differs" in gap.problem for gap in runs.gaps), "the paper runs are reported"
    finish(run, cfg)
    exp = Runs(clone / "runs", clone / "records").experiment("mountaincar_ppo")
    assert (exp.budget, [t.source for t in exp.trials]) == ("paper", ["run", "run", "run"])

COMMITTED = Path(__file__).resolve().parent.parent / "results"


def test_committed_tables_regenerate_from_the_committed_records(tmp_path: Path) -> None:
    """What a fresh clone gets: the collector over results/records alone writes the committed tables."""
    render_all(tmp_path / "runs", tmp_path / "out", only=list(TABLES), records_dir=COMMITTED / "records")
    for name in TABLES:
        assert (tmp_path / "out" / "tables" / f"{name}.csv").read_text() == \
            (COMMITTED / "tables" / f"{name}.csv").read_text(), f"results/tables/{name}.csv differs"


def test_an_unfinished_copy_of_a_recorded_trial_is_not_carried(tmp_path: Path) -> None:
    """A stale run dir of a trial that finished elsewhere (its record holds it done, same config)
    is skipped: no partial record beside the finished one."""
    records, rng, key = tmp_path / "records", np.random.default_rng(0), "mountaincar_ppo/default/seed=0"
    finished, cfg = make_run(tmp_path / "gpu" / "runs", "mountaincar_ppo", 0)
    fill(finished, cfg, rng)
    finish(finished, cfg)
    assert export_records(tmp_path / "gpu" / "runs", records).written == [key]
    stale, cfg = make_run(tmp_path / "cpu" / "runs", "mountaincar_ppo", 0)
    fill(stale, cfg, rng)
    (stale.path / "checkpoints" / "ppo-0000002.zip").write_bytes(b"weights at iteration 2")
    (stale.path / "checkpoints" / "latest.json").write_text(json.dumps(
        {"model": "ppo-0000002.zip", "normalization": None, "progress": {"iteration": 2}, "rng": {}}))
    finish(stale, cfg, state="stopped")
    done = export_records(tmp_path / "cpu" / "runs", records)
    assert done.partial == [] and done.skipped == [f"{key}: status stopped (its record holds this trial, finished)"]
    assert not (records / "partial").exists()
