"""Pending records: an unfinished trial whose checkpoint is not carried (a DBC-runner trial, whose
snapshot holds a replay buffer, or one over the cap of a partial record) leaves its metrics so far
in the records, so a lost machine does not take its curve along. The record is evidence only: it
keeps the furthest attempt, no run resumes from it, the dry run names it beside a trial that is
behind it, and the finished record replaces it."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from plls_bench.core.atomic_files import read_json, read_jsonl
from plls_bench.pipeline import record_export as export
from plls_bench.pipeline.plan import plan_profile
from plls_bench.pipeline.record_export import REPLAY_NOT_CARRIED, export_records
from plls_bench.pipeline.record_export import main as records_main
from plls_bench.reproduce import format_plan
from plls_bench.rundirs.record_layout import PARTIAL_DIR, PENDING_DIR
from plls_bench.rundirs.run_dir import Run
from tests.synthetic_runs import finish, make_run

KEY = "cheetah_dbc/default/seed=0"


def _trained_to(run: Run, iterations: range) -> Run:
    """Eval rows at ``iterations`` and a synthetic DBC checkpoint (64 KiB ``dbc.pt``, one replay
    chunk) at the last of them."""
    for iteration in iterations:
        run.log("eval", {"iteration": iteration, "env_steps": 4 * iteration, "return_mean": iteration / 100})
    last = iterations[-1]
    run.write_bytes(f"checkpoints/replay/chunk_000000000000_{last + 1:012d}.npz", b"r" * 1000)
    run.write_json("checkpoints/progress.json", {"iteration": last, "agent_steps": last, "replay_written": last + 1})
    run.write_bytes("checkpoints/dbc.pt", bytes(range(256)) * 256)
    return run


def test_an_uncarried_trial_leaves_its_metrics_as_a_pending_record(tmp_path: Path) -> None:
    runs = tmp_path / "results" / "runs"
    run = _trained_to(make_run(runs, "cheetah_dbc", 0)[0], range(0, 60, 10))
    done = export_records(runs)
    pending = tmp_path / "results" / "records" / PENDING_DIR / KEY
    assert done.pending == [KEY] and done.partial == []
    assert done.skipped == [f"{KEY}: status running ({REPLAY_NOT_CARRIED})"], "carried at no size"
    assert read_jsonl(pending / "metrics" / "eval.jsonl") == read_jsonl(run.path / "metrics" / "eval.jsonl")
    marker = read_json(pending / "pending.json")
    assert marker["iteration"] == 50 and marker["resumable"] is False and marker["state"] == "running"
    assert marker["not_carried"] == REPLAY_NOT_CARRIED
    assert not (pending / "checkpoints").exists(), "metrics only: the checkpoint stays in the run dir"
    assert not (tmp_path / "results" / "records" / PARTIAL_DIR).exists()
    assert export_records(runs).unchanged == 1, "the same run exports the same record"


def test_a_pending_record_keeps_the_furthest_attempt_and_the_dry_run_names_it(
        tmp_path: Path) -> None:
    runs = tmp_path / "results" / "runs"
    _trained_to(make_run(runs, "cheetah_dbc", 0)[0], range(0, 60, 10))
    export_records(runs)
    shutil.rmtree(runs)  # the machine that held the run dir is gone

    [plan] = plan_profile("quick", str(runs), only=["cheetah_dbc"], rates={})
    trial = plan.trials[0]
    assert (trial.resumes_at, trial.resumes_from, trial.lost_at) == (0, "", 50), "nothing resumes from it"
    assert "behind: cheetah_dbc seed=0 at iteration 0/50,000; an earlier attempt reached 50" in format_plan([plan], 1)

    restarted = _trained_to(make_run(runs, "cheetah_dbc", 0)[0], range(0, 30, 10))
    pending = tmp_path / "results" / "records" / PENDING_DIR / KEY
    done = export_records(runs)
    assert done.pending == [] and f"{KEY}: no pending record written (its pending record is kept: an earlier " \
                                  "attempt reached iteration 50, this run 20)" in done.skipped
    assert read_json(pending / "pending.json")["iteration"] == 50
    [plan] = plan_profile("quick", str(runs), only=["cheetah_dbc"], rates={})
    assert (plan.trials[0].resumes_at, plan.trials[0].lost_at) == (20, 50)

    _trained_to(restarted, range(30, 70, 10))
    assert export_records(runs).pending == [KEY], "past the earlier attempt, the record follows the run"
    assert read_json(pending / "pending.json")["iteration"] == 60
    assert plan_profile("quick", str(runs), only=["cheetah_dbc"], rates={})[0].trials[0].lost_at == 0


def test_a_finished_trial_replaces_its_pending_record(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    runs = tmp_path / "results" / "runs"
    run, cfg = make_run(runs, "cheetah_dbc", 0)
    _trained_to(run, range(0, 60, 10))
    assert records_main(["--runs", str(runs)]) == 0
    assert f"[records] wrote pending record {KEY} (its metrics so far" in capsys.readouterr().out
    shutil.rmtree(run.path / "checkpoints")  # the synthetic dbc.pt holds no policy to record
    finish(run, cfg)
    assert export_records(runs).written == [KEY]
    records = tmp_path / "results" / "records"
    assert (records / KEY / "status.json").is_file()
    assert not (records / PENDING_DIR).exists(), "no empty pending/ folders are left behind"


def test_a_run_without_metrics_writes_no_pending_record(tmp_path: Path) -> None:
    runs = tmp_path / "results" / "runs"
    make_run(runs, "cheetah_dbc", 0)
    done = export_records(runs)
    assert done.pending == [] and done.skipped == [f"{KEY}: status running ({REPLAY_NOT_CARRIED})"]
    assert not (tmp_path / "results" / "records").exists()


def test_a_carried_run_behind_a_pending_record_leaves_it_until_it_passes_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, dbc_carried: None) -> None:
    """The attempt lost with its machine reached 50; the trial restarted under a cap that carries
    it: its partial record is written, and the pending record stays until the run passes 50."""
    runs = tmp_path / "results" / "runs"
    with monkeypatch.context() as patch:
        patch.setattr(export, "MAX_PARTIAL_BYTES", 2**15)
        _trained_to(make_run(runs, "cheetah_dbc", 0)[0], range(0, 60, 10))
        export_records(runs)
    shutil.rmtree(runs)  # the machine that held the run dir is gone
    restarted = _trained_to(make_run(runs, "cheetah_dbc", 0)[0], range(0, 30, 10))
    records = tmp_path / "results" / "records"
    assert export_records(runs).partial == [KEY]
    assert read_json(records / PENDING_DIR / KEY / "pending.json")["iteration"] == 50, "the furthest curve stays"
    [plan] = plan_profile("quick", str(runs), only=["cheetah_dbc"], rates={})
    assert (plan.trials[0].resumes_at, plan.trials[0].lost_at) == (20, 50)

    _trained_to(restarted, range(30, 70, 10))
    assert export_records(runs).partial == [KEY]
    assert not (records / PENDING_DIR).exists(), "past the earlier attempt, the partial record holds the curve"
