"""The training skeleton with a toy trainer: the order of its steps, the eval and checkpoint
cadence it asks the trainer about, and resume (rows newer than the checkpoint dropped, no
re-evaluation of the checkpoint's point)."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from plls_bench.core.metric_rows import EvalRow, TrainRow
from plls_bench.rundirs.run_dir import Run
from plls_bench.train import loop
from plls_bench.train.loop import Progress, TimeLimitReached
from tests.conftest import compose_preset


class Toy:
    """Five iterations of two agent steps, evaluating every second iteration, checkpointing
    after evaluations only; ``crash_at`` raises in that iteration, as a kill would end it."""

    unit, iterations = "iter", 5

    def __init__(self, run: Run, crash_at: int | None = None) -> None:
        self.run, self.crash_at, self.calls, self.saved = run, crash_at, [], None
        self.ahead: dict[int, float] = {}  # iteration -> the trainer's estimate of the interval from there

    def setup(self) -> None:
        self.calls.append("setup")

    def restore(self) -> Progress | None:
        self.calls.append("restore")
        saved = self.run.path / "toy.txt"
        if not saved.exists():
            return None
        iteration, agent_steps, env_steps, evaluations = map(int, saved.read_text().split())
        return Progress(iteration, agent_steps, env_steps=env_steps, evaluations=evaluations)

    def start(self, at: Progress, resumed: bool) -> None:
        self.calls.append(f"start {at.iteration} {resumed}")

    def train_iteration(self, at: Progress) -> tuple[Progress, dict[str, Any] | None]:
        if at.iteration + 1 == self.crash_at:
            raise KeyboardInterrupt
        self.calls.append(f"train {at.iteration + 1}")
        return replace(at, iteration=at.iteration + 1, agent_steps=at.agent_steps + 2,
                       env_steps=at.env_steps + 8), {"loss/x": float(at.iteration)}

    def eval_due(self, at: Progress) -> bool:
        return at.iteration % 2 == 0 or at.iteration == self.iterations

    def evaluate(self, at: Progress) -> EvalRow:
        self.calls.append(f"evaluate {at.iteration}")
        return EvalRow.at(at, episode_returns=[float(at.iteration)], episode_lengths=[1],
                          return_mean=float(at.iteration))

    def report(self, at: Progress, row: TrainRow | None, evaluation: EvalRow | None) -> None:
        self.calls.append(f"report {at.evaluations}")

    def checkpoint_due(self, at: Progress, evaluated: bool) -> bool:
        return evaluated

    def checkpoint(self, at: Progress) -> None:
        self.calls.append(f"checkpoint {at.iteration}")
        self.run.write_bytes("toy.txt", f"{at.iteration} {at.agent_steps} {at.env_steps} {at.evaluations}".encode())

    def interval_ahead_s(self, at: Progress) -> float:
        return self.ahead.get(at.iteration, 0.0)

    def close(self) -> None:
        self.calls.append("close")


def test_skeleton_order_cadence_and_resume(runs_dir: Path) -> None:
    cfg = compose_preset("mountaincar_ppo", runs_dir)
    run = Run(runs_dir / "toy")
    first = Toy(run, crash_at=4)
    try:
        loop.train(first, run, cfg)
    except KeyboardInterrupt:
        pass
    assert first.calls == ["setup", "restore", "start 0 False", "evaluate 0", "report 1", "checkpoint 0",
                           "train 1", "report 1", "train 2", "evaluate 2", "report 2", "checkpoint 2",
                           "train 3", "report 2", "close"]
    assert [r["iteration"] for r in run.read_metrics("train")] == [1, 2, 3]
    second = Toy(run)
    loop.train(second, run, cfg)
    assert second.calls == ["setup", "restore", "start 2 True", "train 3", "report 2", "train 4", "evaluate 4",
                            "report 3", "checkpoint 4", "train 5", "evaluate 5", "report 4", "checkpoint 5",
                            "close"], "no re-evaluation at the checkpoint's iteration 2"
    trains, evals = run.read_metrics("train"), run.read_metrics("eval")
    assert [r["iteration"] for r in trains] == [1, 2, 3, 4, 5], "row 3 of the killed start dropped, redone"
    assert [r["iteration"] for r in evals] == [0, 2, 4, 5]
    assert [r["env_steps"] for r in evals] == [0, 16, 32, 40] and evals[-1]["agent_steps"] == 10
    assert all(r["wall_s"] >= 0 for r in trains) and set(trains[0]) == {"iteration", "agent_steps", "env_steps",
                                                                        "wall_s", "loss/x"}


def test_every_checkpoint_saves_and_restores_the_whole_progress() -> None:
    """One record for PPO's latest.json and DBC's dbc.pt (plls_bench.train.checkpoint)."""
    from plls_bench.train.checkpoint import progress_record, restored_progress

    at = Progress(iteration=7, agent_steps=70, wall_s=1.5, env_steps=280, evaluations=3, episodes=2)
    assert restored_progress(progress_record(at)) == at


def test_checkpoints_written_before_the_shared_record_restore_as_they_did() -> None:
    """PPO's latest.json held (iteration, agent_steps, wall_s); DBC's dbc.pt no iteration."""
    from plls_bench.train.checkpoint import restored_progress

    ppo = restored_progress({"iteration": 4, "agent_steps": 2048, "wall_s": 9.0}, action_repeat=1)
    assert ppo == Progress(iteration=4, agent_steps=2048, wall_s=9.0, env_steps=2048)
    dbc = {"agent_steps": 100, "env_steps": 400, "episodes": 2, "evaluations": 3, "wall_s": 5.0, "replay_written": 102}
    assert restored_progress(dbc) == Progress(iteration=100, agent_steps=100, wall_s=5.0, env_steps=400,
                                              evaluations=3, episodes=2)


def test_a_long_interval_the_trainer_foretells_stops_the_run_before_it(runs_dir: Path) -> None:
    """DBC's burst of updates: the intervals before it are short, so only the trainer's own
    estimate can stop the run at the checkpoint before it; a resumed run checks it before its
    first interval, with no training and nothing written past the checkpoint."""
    cfg = compose_preset("mountaincar_ppo", runs_dir, "time_limit_min=60")
    run = Run(runs_dir / "toy")
    first = Toy(run)
    first.ahead = {2: 7200.0}  # two hours from iteration 2's checkpoint, over the hour's limit
    with pytest.raises(TimeLimitReached, match="iteration 2"):
        loop.train(first, run, cfg)
    assert first.calls[-2:] == ["checkpoint 2", "close"]
    again = Toy(run)
    again.ahead = {2: 7200.0}
    with pytest.raises(TimeLimitReached, match="iteration 2"):
        loop.train(again, run, cfg)
    assert again.calls == ["setup", "restore", "start 2 True", "close"]
    assert [r["iteration"] for r in run.read_metrics("train")] == [1, 2]
    unlimited = Toy(run)
    unlimited.ahead = {2: 7200.0}  # no time limit: never asked, never stops
    loop.train(unlimited, run, compose_preset("mountaincar_ppo", runs_dir))
    assert unlimited.calls[-2:] == ["checkpoint 5", "close"]
