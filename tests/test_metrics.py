"""Typed metric rows: old-format runs and the committed records read into TrainRow / EvalRow and
write back byte for byte; the collector's labels and scales come from one place, not per algorithm."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from plls_bench.core.atomic_files import read_jsonl
from plls_bench.core.metric_rows import EvalRow, TrainRow, parallel_envs
from plls_bench.pipeline.runner_registry import iteration_label
from plls_bench.report.evidence.trials import Trial
from plls_bench.train.loop import Progress
from tests.synthetic_runs import make_run, write_eval

RECORDS = Path(__file__).resolve().parent.parent / "results" / "records"


def _trial(run_dir: Path) -> Trial:
    return Trial(0, run_dir, "done", json.loads((run_dir / "config.json").read_text())["config"])


@pytest.mark.parametrize("experiment", ["mountaincar_plls_ppo", "cheetah_dbc"])
def test_old_format_synthetic_rows_read_into_the_rows_the_runners_write(experiment: str, runs_dir: Path) -> None:
    """The synthetic writer builds rows by hand, as the runners did before the typed rows: read
    back they are the EvalRow / TrainRow a runner writes at the same point, and write back as read."""
    run, cfg = make_run(runs_dir, experiment, seed=0)
    write_eval(run, cfg, [0, 2, 4], [[1.0, 3.0], [2.0, 4.0], [5.0, 7.0]])
    evals, trains = run.read_metrics("eval"), run.read_metrics("train")
    assert len(evals) == 3 and trains, "the rows written are read back"
    for record in evals:
        row = EvalRow.from_record(record)
        assert row is not None and row.to_record() == record
        at = Progress(iteration=record["iteration"], agent_steps=record["agent_steps"], wall_s=record["wall_s"],
                      env_steps=record["env_steps"])
        written = EvalRow.at(at, episode_returns=record["episode_returns"], episode_lengths=record["episode_lengths"],
                             return_mean=record["return_mean"],
                             episode_returns_stochastic=record.get("episode_returns_stochastic"))
        assert written == row
        assert row.return_mean == np.mean(record["episode_returns"]) and row.x("iteration") == record["iteration"]
    for record in trains:
        row = TrainRow.from_record(record)
        assert row.to_record() == record and row.agent_steps is None  # the synthetic train rows lack it
        assert row.metrics == {"loss/policy": 0.1, "loss/value": 1.0, "perf/sps": 1000.0}
    trial = _trial(run.path)
    ppo = cfg.algo.name == "ppo"
    assert parallel_envs(trial.cfg) == (cfg.algo.ppo.n_envs if ppo else 1)
    assert iteration_label(trial.cfg) == (f"PPO iteration ({cfg.algo.ppo.n_envs} envs x {cfg.algo.ppo.n_steps} steps)"
                                          if ppo else "iteration (agent steps)")


def test_an_eval_row_without_return_mean_reads_its_episodes_mean() -> None:
    old = {"iteration": 3, "env_steps": 12, "agent_steps": 3, "wall_s": 1.0, "episode_returns": [1.0, 2.0]}
    row = EvalRow.from_record(old)
    assert row is not None and row.return_mean == 1.5 and row.episode_lengths == []
    assert EvalRow.from_record({"iteration": 3, "episode_returns": []}) is None
    nan = EvalRow.from_record({"iteration": 3, "return_mean": float("nan"), "episode_returns": [2.0]})
    assert nan is not None and nan.return_mean == 2.0
    bare = EvalRow.from_record({"return_mean": 1.0, "episode_returns": [1.0]})
    assert bare is not None and bare.x("iteration") is None


def test_committed_records_round_trip_through_the_typed_rows() -> None:
    """Every row of results/records reads into a typed row that writes back as it is on disk."""
    files = sorted(RECORDS.glob("*/*/seed=*/metrics/*.jsonl"))
    streams = {path.name for path in files}
    assert {"train.jsonl", "eval.jsonl"} <= streams
    for path in files:
        if path.name == "eval.jsonl":
            for record in read_jsonl(path):
                row = EvalRow.from_record(record)
                assert row is not None and row.to_record() == record, path
        elif path.name == "train.jsonl":
            for record in read_jsonl(path):
                assert TrainRow.from_record(record).to_record() == record, path
