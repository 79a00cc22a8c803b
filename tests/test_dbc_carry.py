"""An unfinished DBC-runner trial carried across machines as a partial record, as exports did
before ``RunnerSpec.snapshot_holds_replay`` (now it never is: test_light_repository.py; the
``dbc_carried`` fixture restores the old rule, so the runner-agnostic carrying and the restore of
partial records written then stay tested at small sizes): state SAC's
checkpoint (``dbc.pt`` with optimisers, over the per-file cap, goes in parts; its replay chunks
travel with it), and what is refused: a record over the whole-record cap (a pixel DBC's), or parts
that no longer join to the file they were cut from; a checkpoint committed while the export reads
it is read again."""
from __future__ import annotations

import logging
import shutil
from pathlib import Path

import pytest

from plls_bench.core.atomic_files import read_json
from plls_bench.pipeline import record_export as export
from plls_bench.pipeline.execute import execute
from plls_bench.pipeline.record_export import export_records
from plls_bench.rundirs.record_layout import PARTIAL_DIR
from plls_bench.rundirs.record_restore import seed_from_partial
from plls_bench.rundirs.record_snapshot import SNAPSHOT_TRIES, ResumeFiles, checkpoint_snapshot
from plls_bench.rundirs.run_dir import Run, run_dir_path
from plls_bench.train import dbc, dbc_state
from tests.conftest import compose_preset
from tests.interrupting import interrupted, rows
from tests.synthetic_runs import make_run

KEY = Path("cheetah_sac_state") / "default" / "seed=0"
SMALL = ("algo.dbc.hidden_dim=32",)  # the real pipeline, small enough for CI


@pytest.fixture
def all_budgets(monkeypatch: pytest.MonkeyPatch) -> None:
    """Export smoke runs too: the real pipeline at its smallest budget stands in for a real one."""
    monkeypatch.setattr(export, "EXCLUDED_BUDGETS", ())


@pytest.mark.slow
def test_an_interrupted_state_sac_trial_continues_from_its_partial_record_in_a_fresh_runs_dir(
        tmp_path: Path, all_budgets: None, one_torch_thread: None, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture, dbc_carried: None) -> None:
    dirs = {name: run_dir_path(tmp_path / name / "results" / "runs", *KEY.parts[:2], 0)
            for name in ("local", "carried")}
    cfgs = {name: compose_preset("cheetah_sac_state", d.parents[2], *SMALL) for name, d in dirs.items()}
    for name in dirs:  # the first evaluation (200 env steps) is the first checkpoint
        interrupted(cfgs[name], dirs[name], dbc.DBCTrainer, 200, monkeypatch)
    assert execute(cfgs["local"], dirs["local"]) == "done"  # resumed from its own checkpoint

    runs = dirs["carried"].parents[2]
    checkpoint = (dirs["carried"] / "checkpoints" / "dbc.pt").read_bytes()
    monkeypatch.setattr(export, "MAX_FILE_BYTES", len(checkpoint) // 3 + 1)  # as a 45 MiB state-SAC dbc.pt is to 16 MiB
    done = export_records(runs)
    partial = runs.parent / "records" / PARTIAL_DIR / KEY
    assert done.partial == [str(KEY)] and not done.skipped
    marker = read_json(partial / "partial.json")
    assert marker["iteration"] == 200 and marker["commit"] == "checkpoints/dbc.pt"
    assert not (partial / "checkpoints" / "dbc.pt").exists()
    assert len(marker["split"]["checkpoints/dbc.pt"]["parts"]) == 3
    assert any(f.startswith("checkpoints/replay/chunk_") for f in marker["files"]), "the replay travels too"

    shutil.rmtree(runs)
    with caplog.at_level(logging.INFO, logger="plls_bench.pipeline.execute"):
        assert execute(cfgs["carried"], dirs["carried"]) == "done"
    assert f"resuming seed=0 from partial record {partial} at iteration 200" in caplog.text
    for stream in ("train", "eval"):
        assert rows(dirs["carried"], stream) == rows(dirs["local"], stream), \
            f"{stream}: resuming from the record is resuming from the checkpoint"
    assert [r["env_steps"] for r in rows(dirs["carried"], "eval")] == [0, 200, 400]
    assert (dirs["carried"] / "checkpoints" / "dbc.pt").read_bytes() != checkpoint, "it trained on"
    assert export_records(runs).written == [str(KEY)] and not partial.exists(), "done replaces partial"


def _checkpoint(run: Run, size: int) -> Run:
    """A synthetic DBC checkpoint in ``run``: a ``size``-byte ``dbc.pt`` and one replay chunk."""
    run.log("eval", {"iteration": 0, "return_mean": 0.0})
    run.write_bytes("checkpoints/replay/chunk_000000000000_000000000051.npz", b"r" * 1000)
    run.write_json("checkpoints/progress.json", {"iteration": 50, "agent_steps": 50, "replay_written": 51})
    run.write_bytes("checkpoints/dbc.pt", bytes(range(256)) * (size // 256))
    return run


def test_a_dbc_record_over_the_whole_record_cap_is_not_carried(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                               dbc_carried: None) -> None:
    runs = tmp_path / "results" / "runs"
    run, _ = make_run(runs, "cheetah_dbc", 0)
    assert export_records(runs).skipped == ["cheetah_dbc/default/seed=0: status running (no checkpoint to carry)"]
    _checkpoint(run, 2**16)
    monkeypatch.setattr(export, "MAX_PARTIAL_BYTES", 2**15)  # as a pixel DBC's 116+ MiB is to 16 MiB
    done = export_records(runs)
    [reason] = done.skipped
    assert reason.startswith("cheetah_dbc/default/seed=0: status running (0.1 MiB to carry, over the 0 MiB")
    assert done.pending == ["cheetah_dbc/default/seed=0"], \
        "its metrics go to a pending record (test_pending_records.py)"
    assert not (tmp_path / "results" / "records" / PARTIAL_DIR).exists()


def test_parts_that_do_not_join_to_the_recorded_file_are_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                dbc_carried: None) -> None:
    runs = tmp_path / "results" / "runs"
    run = _checkpoint(make_run(runs, "cheetah_sac_state", 0)[0], 2**14)
    monkeypatch.setattr(export, "MAX_FILE_BYTES", 2**12)  # above the record's json files, below dbc.pt
    assert export_records(runs).partial == [str(KEY)]
    record = tmp_path / "results" / "records" / PARTIAL_DIR / KEY
    cfg_hash = read_json(record / "partial.json")["config_hash"]
    shutil.rmtree(runs)
    assert seed_from_partial(run.path, runs, cfg_hash) == (record, 50)
    assert (run.path / "checkpoints" / "dbc.pt").read_bytes() == bytes(range(256)) * 64, "joined in order"

    shutil.rmtree(runs)
    (record / "checkpoints" / "dbc.pt.part-002").write_bytes(b"x" * 2**12)
    with pytest.raises(RuntimeError, match="the parts of checkpoints/dbc.pt do not join to the file it recorded"):
        seed_from_partial(run.path, runs, cfg_hash)
    assert not (run.path / "checkpoints" / "dbc.pt").exists(), "no checkpoint from a damaged record"


def _committing(run: Run, commits: list[str]) -> ResumeFiles:
    """DBC's ``committed_files`` that, at its calls listed in ``commits`` (one string per call:
    "" nothing, "chunk" a new replay chunk with its checkpoint, "pt" a rewritten ``dbc.pt``
    alone), first commits a newer checkpoint, as a run still training does while it is exported."""
    calls = iter(commits)

    def listing(run_path: Path) -> tuple[list[str], int] | None:
        change = next(calls, "")
        if change == "chunk":
            end = read_json(run.path / "checkpoints" / "progress.json")["replay_written"] + 9
            run.log("train", {"iteration": end - 1})
            run.write_bytes(f"checkpoints/replay/chunk_{end - 9:012d}_{end:012d}.npz", b"n" * 1000)
        if change:
            old = (run.path / "checkpoints" / "dbc.pt").read_bytes()
            run.write_bytes("checkpoints/dbc.pt", change.encode() * 100 + old)
        if change == "chunk":
            run.write_json("checkpoints/progress.json",
                           {"iteration": end - 1, "agent_steps": end - 1, "replay_written": end})
        return dbc_state.committed_files(run_path)
    return listing


@pytest.mark.parametrize("change", ["chunk", "pt"])
def test_a_checkpoint_committed_while_it_is_read_is_read_again(tmp_path: Path, change: str) -> None:
    """The first read sees the checkpoint of iteration 50; before it ends the run commits another
    (a new chunk, dbc.pt and progress, or dbc.pt alone): the snapshot is the second, whole."""
    run = _checkpoint(make_run(tmp_path / "runs", "cheetah_dbc", 0)[0], 2**12)
    snapshot = checkpoint_snapshot(run.path, _committing(run, ["", change]), 2**20)
    assert not isinstance(snapshot, str), snapshot
    contents, files, iteration = snapshot
    assert contents["checkpoints/dbc.pt"] == (run.path / "checkpoints" / "dbc.pt").read_bytes(), "the newer dbc.pt"
    assert files[-1] == "checkpoints/dbc.pt" and set(files) <= set(contents)
    chunks = sorted(f for f in files if f.startswith("checkpoints/replay/"))
    if change == "chunk":
        assert iteration == 59 and chunks[-1].endswith("_000000000060.npz"), "the chunk dbc.pt needs came too"
        assert b'"iteration": 59' in contents["metrics/train.jsonl"], "and the rows up to it"
    else:
        assert iteration == 50 and len(chunks) == 1


def test_a_checkpoint_that_keeps_changing_is_not_carried(tmp_path: Path) -> None:
    run = _checkpoint(make_run(tmp_path / "runs", "cheetah_dbc", 0)[0], 2**12)
    reason = checkpoint_snapshot(run.path, _committing(run, ["", "pt"] * SNAPSHOT_TRIES), 2**20)
    assert reason == (f"its checkpoint changed during each of {SNAPSHOT_TRIES} reads (a run still training); "
                      "export after it stops")


@pytest.mark.slow
def test_dbc_checkpoints_at_each_episode_end_and_resumes_from_one(
        tmp_path: Path, one_torch_thread: None, monkeypatch: pytest.MonkeyPatch) -> None:
    """Episodes of 150 steps, evaluations every 200: checkpoints at 0, 150, 200, 300 and 400, so a
    deadline costs at most an episode. Interrupted after the one at 300 (an episode end, not an
    evaluation), the run resumes there: every row once, the evaluations as an unbroken run's."""
    overrides = (*SMALL, "env.max_episode_steps=150")
    dirs = {name: run_dir_path(tmp_path / name / "runs", *KEY.parts[:2], 0) for name in ("whole", "resumed")}
    cfgs = {name: compose_preset("cheetah_sac_state", d.parents[2], *overrides) for name, d in dirs.items()}
    saved: list[int] = []
    real = dbc.DBCTrainer.checkpoint
    with monkeypatch.context() as patch:
        patch.setattr(dbc.DBCTrainer, "checkpoint", lambda self, at: (saved.append(at.iteration), real(self, at)))
        assert execute(cfgs["whole"], dirs["whole"]) == "done"
    assert saved == [0, 150, 200, 300, 400]

    interrupted(cfgs["resumed"], dirs["resumed"], dbc.DBCTrainer, 300, monkeypatch)
    assert read_json(dirs["resumed"] / "checkpoints" / "progress.json")["iteration"] == 300
    assert execute(cfgs["resumed"], dirs["resumed"]) == "done"
    for stream in ("train", "eval"):
        iterations = [r["iteration"] for r in rows(dirs["resumed"], stream)]
        assert iterations == [r["iteration"] for r in rows(dirs["whole"], stream)], f"{stream}: no row lost or twice"
    assert rows(dirs["resumed"], "eval")[:2] == rows(dirs["whole"], "eval")[:2], "the same run up to the checkpoint"
