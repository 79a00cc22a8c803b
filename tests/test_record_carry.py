"""Records as carried evidence: reproduce counts recorded trials as done, a recorded policy is
filmed and evaluated with an empty runs dir (its V_s / V_a restored from the records, no dataset),
and an interrupted PPO trial continues in a fresh runs dir from its partial record (DBC's: test_dbc_carry.py)."""
from __future__ import annotations

import logging
import shutil
from pathlib import Path

import numpy as np
import pytest

from plls_bench.core.atomic_files import atomic_write_json, read_json
from plls_bench.film import film_run
from plls_bench.pipeline import record_export as export
from plls_bench.pipeline.execute import execute
from plls_bench.pipeline.plan import plan_profile
from plls_bench.pipeline.record_export import export_records
from plls_bench.report.evidence.load import Runs
from plls_bench.reproduce import format_plan
from plls_bench.rundirs.record_layout import PARTIAL_DIR
from plls_bench.rundirs.run_dir import Run, config_hash, run_dir_path
from plls_bench.train import ppo
from plls_bench.train.schedule import Schedule
from tests.conftest import compose_preset
from tests.interrupting import interrupted, rows
from tests.synthetic_runs import make_run
from tests.test_reproduce import reproduce

KEY = Path("default") / "seed=0"


@pytest.fixture
def all_budgets(monkeypatch: pytest.MonkeyPatch) -> None:
    """Export smoke runs too: the real pipeline at its smallest budget stands in for a real one."""
    monkeypatch.setattr(export, "EXCLUDED_BUDGETS", ())


def test_reproduce_counts_recorded_trials_as_done_unless_asked_to_rerun(tmp_path: Path) -> None:
    runs = tmp_path / "results" / "runs"
    cfg = compose_preset("mountaincar_data", runs)
    record = Run(tmp_path / "results" / "records" / "mountaincar_data" / KEY)
    record.write_status("done", config_hash=config_hash(cfg))
    [plan] = plan_profile("smoke", str(runs), only=["mountaincar_data"], rates={})
    assert plan.recorded == 1 and plan.pending == []
    [again] = plan_profile("smoke", str(runs), only=["mountaincar_data"], rates={}, count_records=False)
    assert again.recorded == 1 and len(again.pending) == 1
    record.write_status("done", config_hash="another config")
    [changed] = plan_profile("smoke", str(runs), only=["mountaincar_data"], rates={})
    assert changed.recorded == 0 and len(changed.pending) == 1, "a record of another config is not done"

    record.write_status("done", config_hash=config_hash(cfg))
    for flag, to_run, verb in (([], "0/1", "counted as done"), (["--rerun-recorded"], "1/1", "run again")):
        shown = reproduce("--profile", "smoke", "--only", "mountaincar_data", "--runs", str(runs), "--dry-run", *flag)
        assert shown.returncode == 0, shown.stderr
        row = next(line.split() for line in shown.stdout.splitlines() if line.startswith("mountaincar_data"))
        assert row[2:4] == [to_run, "1"], shown.stdout  # to run, recorded
        assert f"1 recorded in committed records, {verb}" in shown.stdout
    assert not runs.exists()


def test_a_partial_record_is_all_or_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An unfinished PPO run is carried with its checkpoint (a file over the per-file cap in parts),
    or not at all (the whole over the partial-record cap)."""
    runs = tmp_path / "results" / "runs"
    run, cfg = make_run(runs, "mountaincar_ppo", 0)
    run.log("eval", {"iteration": 0, "return_mean": 1.0})
    run.write_bytes("checkpoints/ppo-0000002.zip", b"w" * 2**20)
    run.write_bytes("checkpoints/vecnormalize-0000002.json", b"{}")
    run.write_json("checkpoints/latest.json", {"model": "ppo-0000002.zip", "normalization": "vecnormalize-0000002.json",
                                               "progress": {"iteration": 2}, "rng": {}})
    monkeypatch.setattr(export, "MAX_PARTIAL_BYTES", 2**20)
    done = export_records(runs)
    assert done.partial == [] and done.skipped == ["mountaincar_ppo/default/seed=0: status running "
                                                   "(1.0 MiB to carry, over the 1 MiB of a partial record)"]
    monkeypatch.setattr(export, "MAX_FILE_BYTES", 2**19)
    monkeypatch.setattr(export, "MAX_PARTIAL_BYTES", 2**21)
    assert export_records(runs).partial == ["mountaincar_ppo/default/seed=0"]
    record = tmp_path / "results" / "records" / PARTIAL_DIR / "mountaincar_ppo" / KEY
    marker = read_json(record / "partial.json")
    assert marker["iteration"] == 2 and marker["commit"] == "checkpoints/latest.json"
    assert {"metrics/eval.jsonl", "checkpoints/ppo-0000002.zip", "checkpoints/vecnormalize-0000002.json",
            "checkpoints/latest.json"} <= set(marker["files"]), "VecNormalize statistics travel with the checkpoint"
    assert marker["split"]["checkpoints/ppo-0000002.zip"]["parts"] == [
        "checkpoints/ppo-0000002.zip.part-000", "checkpoints/ppo-0000002.zip.part-001"]
    assert max(p.stat().st_size for p in record.rglob("*")) <= 2**19


@pytest.mark.slow
def test_a_recorded_policy_is_filmed_and_evaluated_with_an_empty_runs_dir(
        tmp_path: Path, all_budgets: None, one_torch_thread: None, caplog: pytest.LogCaptureFixture) -> None:
    from plls_bench.repr.store import load_representations
    from plls_bench.train.ppo_model import build_vec_env, load_trained

    runs = tmp_path / "results" / "runs"
    cfg = compose_preset("mountaincar_plls_ppo", runs)  # builds the dataset and V_a, then trains
    run_dir = run_dir_path(runs, "mountaincar_plls_ppo", "default", 0)
    assert execute(cfg, run_dir) == "done"
    original = film_run(run_dir, tmp_path / "strip_run", device="cpu")
    venv = build_vec_env(cfg, 2, seed=3, reprs=load_trained(run_dir, "cpu").reprs)
    obs = venv.reset()
    venv.close()
    actions = load_trained(run_dir, "cpu").act(obs)

    done = export_records(runs)
    assert done.written == ["mountaincar_plls_ppo/default/seed=0"] and len(done.artifacts) == 1
    records = tmp_path / "results" / "records"
    record = records / "mountaincar_plls_ppo" / KEY
    shutil.rmtree(runs)  # a fresh clone: only the committed records
    assert not list((records / "artifacts").glob("data*")), "datasets are never recorded"

    meta = film_run(record, tmp_path / "strip_record", device="cpu")
    assert meta["episode_return"] == original["episode_return"] and meta["checkpoint"] == original["checkpoint"]
    frames = "frames.npz"
    assert (tmp_path / "strip_record" / frames).read_bytes() == (tmp_path / "strip_run" / frames).read_bytes()
    np.testing.assert_array_equal(load_trained(record, "cpu").act(obs), actions)

    with caplog.at_level(logging.INFO, logger="plls_bench.repr.store"):
        reprs = load_representations(cfg)  # the runs dir's own lookup: restored, not trained
    [kind_hash] = done.artifacts
    assert f"V_a artifact {kind_hash} restored from record {records / 'artifacts' / kind_hash}" in caplog.text
    assert reprs.action_vae is not None and (runs / "artifacts" / kind_hash / "key.json").is_file()
    assert not (runs / "artifacts" / "data").exists(), "restoring V_a needs no dataset"


@pytest.mark.slow
def test_an_interrupted_ppo_trial_continues_from_its_partial_record_in_a_fresh_runs_dir(
        tmp_path: Path, all_budgets: None, one_torch_thread: None, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture) -> None:
    overrides = ("budget.train_env_steps=5120", "budget.eval_every_env_steps=1024")  # 10 iterations
    dirs = {name: run_dir_path(tmp_path / name / "results" / "runs", "mountaincar_ppo", "default", 0)
            for name in ("whole", "local", "carried")}
    cfgs = {name: compose_preset("mountaincar_ppo", d.parents[2], *overrides) for name, d in dirs.items()}
    assert execute(cfgs["whole"], dirs["whole"]) == "done"
    for name in ("local", "carried"):
        interrupted(cfgs[name], dirs[name], ppo.PPOTrainer, 4, monkeypatch)
    assert execute(cfgs["local"], dirs["local"]) == "done"  # resumed from its own checkpoint

    runs = dirs["carried"].parents[2]
    done = export_records(runs)
    partial = runs.parent / "records" / PARTIAL_DIR / "mountaincar_ppo" / KEY
    assert done.partial == ["mountaincar_ppo/default/seed=0"] and not done.written
    assert read_json(partial / "partial.json")["iteration"] == 4
    shutil.rmtree(runs)
    assert Runs(runs, runs.parent / "records").experiment("mountaincar_ppo").trials == [], \
        "partial records are not read"
    with caplog.at_level(logging.INFO, logger="plls_bench.pipeline.execute"):
        assert execute(cfgs["carried"], dirs["carried"]) == "done"
    assert f"resuming seed=0 from partial record {partial} at iteration 4" in caplog.text

    for stream in ("train", "eval"):
        carried, local, whole = (rows(dirs[n], stream) for n in ("carried", "local", "whole"))
        assert [r["iteration"] for r in carried] == [r["iteration"] for r in whole], "no row lost or duplicated"
        assert carried == local, f"{stream}: resuming from the record is resuming from the checkpoint"
        assert [r for r in carried if r["iteration"] <= 4] == [r for r in whole if r["iteration"] <= 4]
    assert len(read_json(dirs["carried"] / "provenance.json")["starts"]) == 2, "the record's start is kept"

    again = export_records(runs)
    assert again.written == ["mountaincar_ppo/default/seed=0"] and not partial.exists(), "done replaces partial"
    assert not (runs.parent / "records" / PARTIAL_DIR).exists(), "no empty folder of it is left"


@pytest.mark.slow
def test_a_recorded_dbc_policy_keeps_its_actor_alone_and_films_the_same(
        tmp_path: Path, all_budgets: None, one_torch_thread: None) -> None:
    from plls_bench.train.dbc_state import POLICY, policy_files

    runs = tmp_path / "results" / "runs"
    run_dir = run_dir_path(runs, "cheetah_plls_dbc", "default", 0)
    assert execute(compose_preset("cheetah_plls_dbc", runs), run_dir) == "done"
    original = film_run(run_dir, tmp_path / "strip_run", device="cpu", max_steps=20)
    export_records(runs)
    record = tmp_path / "results" / "records" / "cheetah_plls_dbc" / KEY
    assert (record / POLICY).stat().st_size < (run_dir / "checkpoints" / "dbc.pt").stat().st_size
    assert not list(record.rglob("dbc.pt")) and not list(record.rglob("chunk_*")), "no optimisers, no replay"
    assert policy_files(record) == {POLICY: (record / POLICY).read_bytes()}, "a record holds a policy to film"
    shutil.rmtree(runs)
    meta = film_run(record, tmp_path / "strip_record", device="cpu", max_steps=20)
    assert meta["checkpoint"] == "dbc_policy.pt" and meta["episode_return"] == original["episode_return"]
    frames = "frames.npz"
    assert (tmp_path / "strip_record" / frames).read_bytes() == (tmp_path / "strip_run" / frames).read_bytes()


def test_the_dry_run_costs_only_what_a_resumed_trial_has_left(tmp_path: Path) -> None:
    """A trial with a partial record (or its own checkpoint, which wins, as in the runner) is
    listed with the iteration it resumes from, and only its remaining training is costed."""
    runs = tmp_path / "results" / "runs"
    cfg = compose_preset("mountaincar_ppo", runs)
    rates = {"train/mountaincar_ppo": 1.0, "eval/mountaincar_ppo": 1.0}
    [fresh] = plan_profile("smoke", str(runs), only=["mountaincar_ppo"], rates=rates)
    total = Schedule.of(cfg).iterations
    assert total >= 2 and fresh.trials[0].resumes_from == "" and fresh.seconds

    marker = {"config_hash": config_hash(cfg), "iteration": total // 2, "files": [], "commit": "x"}
    atomic_write_json(tmp_path / "results" / "records" / PARTIAL_DIR / "mountaincar_ppo" / KEY / "partial.json", marker)
    [resumed] = plan_profile("smoke", str(runs), only=["mountaincar_ppo"], rates=rates)
    trial = resumed.trials[0]
    assert (trial.resumes_at, trial.resumes_from, trial.iterations) == (total // 2, "partial record", total)
    assert resumed.seconds == pytest.approx(fresh.seconds * (1 - (total // 2) / total))
    assert f"resumes: mountaincar_ppo seed=0 at iteration {total // 2}/{total} (from its partial record)" in \
        format_plan([resumed], 1)

    run, _ = make_run(runs, "mountaincar_ppo", 0, "smoke")
    run.write_json("checkpoints/latest.json", {"model": "ppo-0000001.zip", "progress": {"iteration": 1}, "rng": {}})
    [local] = plan_profile("smoke", str(runs), only=["mountaincar_ppo"], rates=rates)
    assert (local.trials[0].resumes_at, local.trials[0].resumes_from) == (1, "run dir")


def test_a_finished_run_never_replaces_a_finished_record_of_another_config(
        tmp_path: Path, all_budgets: None, one_torch_thread: None) -> None:
    """A record slot is experiment/variant/seed whatever the budget: a finished trial of another
    config (a longer budget) is held as a partial record, the next launch of that config in a fresh
    runs dir restores it as done without a duplicated row, and ``replace`` swaps the records."""
    records = tmp_path / "results" / "records"
    configs = {name: ("budget.train_env_steps=2048", f"budget.eval_every_env_steps={every}")
               for name, every in (("short", 1024), ("other", 2048))}
    dirs = {name: run_dir_path(tmp_path / name / "runs", "mountaincar_ppo", "default", 0)
            for name in ("short", "other", "fresh")}
    cfgs = {name: compose_preset("mountaincar_ppo", d.parents[2], *configs["short" if name == "short" else "other"])
            for name, d in dirs.items()}
    for name in ("short", "other"):
        assert execute(cfgs[name], dirs[name]) == "done"
    assert export_records(dirs["short"].parents[2], records).written == ["mountaincar_ppo/default/seed=0"]

    held = export_records(dirs["other"].parents[2], records)
    assert not held.written and held.partial == ["mountaincar_ppo/default/seed=0"] and len(held.held) == 1
    assert "another config" in held.held[0] and config_hash(cfgs["short"]) in held.held[0]
    record = Run(records / "mountaincar_ppo" / KEY)
    assert record.read_config()["config_hash"] == config_hash(cfgs["short"]), "the finished record stays"

    fresh_runs = dirs["fresh"].parents[2]
    shutil.copytree(records, fresh_runs.parent / "records")  # a fresh clone's records beside its runs dir
    assert execute(cfgs["fresh"], dirs["fresh"]) == "done"
    assert rows(dirs["fresh"], "eval") == rows(dirs["other"], "eval"), "restored as done, no row twice"

    replaced = export_records(dirs["other"].parents[2], records, replace=True)
    assert replaced.written == ["mountaincar_ppo/default/seed=0"]
    assert record.read_config()["config_hash"] == config_hash(cfgs["other"])
    assert not (records / PARTIAL_DIR).exists(), "the held partial record goes, empty folders with it"
