"""``time_limit_min``: a learner stops at a checkpoint before its limit, status ``stopped``, and the
next launch resumes it to the same complete history; the key changes no hash and no run dir."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from plls_bench.config import ConfigError
from plls_bench.plan import plan_profile
from plls_bench.reproduce import parse_args
from plls_bench.runner import execute
from plls_bench.runs import Run, config_hash
from plls_bench.train.loop import TimeLimit
from plls_bench.train.schedule import Schedule
from tests.conftest import compose_preset
from tests.test_ppo_runs import check_run_contract


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_time_limit_stops_when_the_longest_interval_would_pass_it() -> None:
    """The longest interval so far, not the last: DBC's interval with an evaluation (here 200 s)
    comes back after short ones that end an episode (50 s, 20 s)."""
    clock = FakeClock()
    limit = TimeLimit(10.0, now=clock)  # 600 s
    clock.t = 100.0  # set-up and restore
    limit.mark()
    clock.t = 300.0  # first checkpoint: 300 s in, the interval took 200 s -> next ends by 500
    assert not limit.stop_after_checkpoint()
    clock.t = 350.0  # interval 50 s, the longest still 200 -> by 550
    assert not limit.stop_after_checkpoint()
    clock.t = 400.0  # by 600, not past the limit
    assert not limit.stop_after_checkpoint()
    clock.t = 420.0  # interval 20 s alone would end by 440, but an interval of 200 would end at 620
    assert limit.stop_after_checkpoint()


def test_time_limit_forgets_an_interval_that_does_not_come_back() -> None:
    """A fresh DBC run's burst of init_steps updates: one long interval (1200 s), then short ones
    (150 s). While the burst is among the last RECENT_INTERVALS it counts (at 2550 s: 2550 + 1200
    would pass 3600); one short interval later it no longer does (2700 + 150)."""
    clock = FakeClock()
    limit = TimeLimit(60.0, now=clock)  # 3600 s
    clock.t = 1200.0
    stops = [limit.stop_after_checkpoint()]
    for _ in range(TimeLimit.RECENT_INTERVALS):
        clock.t += 150.0
        stops.append(limit.stop_after_checkpoint())
    assert stops == [False] * 9 + [True, False]
    assert clock.t == 2700.0


def test_no_limit_never_stops() -> None:
    clock = FakeClock()
    limit = TimeLimit(0.0, now=clock)
    clock.t = 1e9
    assert not limit.stop_after_checkpoint()


def test_negative_time_limit_is_refused_naming_the_key(runs_dir: Path) -> None:
    with pytest.raises(ConfigError, match="time_limit_min"):
        compose_preset("mountaincar_ppo", runs_dir, "time_limit_min=-1")


def test_time_limit_changes_neither_hash_nor_run_dir(runs_dir: Path) -> None:
    plain = compose_preset("mountaincar_ppo", runs_dir)
    limited = compose_preset("mountaincar_ppo", runs_dir, "time_limit_min=30")
    assert limited.time_limit_min == 30 and config_hash(limited) == config_hash(plain)
    dirs = [[t.run_dir for p in plan_profile("smoke", str(runs_dir), ["mountaincar_ppo"], overrides=o) for t in p.trials]
            for o in ((), ("time_limit_min=30",))]
    assert dirs[0] == dirs[1] and all("time_limit" not in str(d.relative_to(runs_dir)) for d in dirs[1])


@pytest.mark.slow
def test_a_stopped_run_resumes_to_the_complete_history(runs_dir: Path) -> None:
    """A limit far below one iteration stops the run after its first checkpointed iteration; the
    next launch without a limit finishes it, every eval and train row once."""
    overrides = ("budget.train_env_steps=2560", "budget.eval_every_env_steps=512")  # 5 iterations
    run_dir = runs_dir / "mountaincar_ppo" / "default" / "seed=0"
    cfg = compose_preset("mountaincar_ppo", runs_dir, *overrides, "time_limit_min=1e-6")
    assert execute(cfg, run_dir) == "stopped"
    status = Run(run_dir).read_status() or {}
    assert status["state"] == "stopped" and status["iteration"] == 1 and "time_limit_min" in status["reason"]
    assert json.loads((run_dir / "checkpoints" / "latest.json").read_text())["progress"]["iteration"] == 1
    assert [r["iteration"] for r in Run(run_dir).read_metrics("train")] == [1]

    cfg = compose_preset("mountaincar_ppo", runs_dir, *overrides)
    assert execute(cfg, run_dir) == "done"
    check_run_contract(run_dir, Schedule.of(cfg), cfg.budget.eval_episodes)
    assert len(json.loads((run_dir / "provenance.json").read_text())["starts"]) == 2


def test_reproduce_refuses_a_negative_time_limit(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        parse_args(["--time-limit-min", "-5"])
    assert "--time-limit-min must be >= 0" in capsys.readouterr().err
