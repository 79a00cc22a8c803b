"""``time_limit_min``: a learner stops at a checkpoint before its limit, status ``stopped``, and the
next launch resumes it to the same complete history; the key changes no hash and no run dir."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from plls_bench.config import ConfigError
from plls_bench.pipeline.execute import execute
from plls_bench.pipeline.plan import plan_profile
from plls_bench.reproduce import parse_args
from plls_bench.rundirs.run_dir import Run, config_hash
from plls_bench.train.loop import TimeLimit
from plls_bench.train.schedule import Schedule
from tests.conftest import compose_preset
from tests.test_ppo_runs import check_run_contract


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_time_limit_stops_when_an_interval_with_an_evaluation_would_pass_it() -> None:
    """The last interval of each kind, not the last interval: DBC's interval with an evaluation
    (here 200 s) comes back after short ones that only end an episode (50 s, 20 s)."""
    clock = FakeClock()
    limit = TimeLimit(10.0, now=clock)  # 600 s
    clock.t = 100.0  # set-up and restore
    limit.mark()
    clock.t = 300.0  # first checkpoint, after an evaluation: 300 s in, 200 s -> next ends by 500
    assert not limit.stop_after_checkpoint(evaluated=True)
    clock.t = 350.0  # 50 s without, the evaluated one still 200 -> by 550
    assert not limit.stop_after_checkpoint(evaluated=False)
    clock.t = 400.0  # by 600, not past the limit
    assert not limit.stop_after_checkpoint(evaluated=False)
    clock.t = 420.0  # 20 s alone would end by 440, but an interval with an evaluation would end at 620
    assert limit.stop_after_checkpoint(evaluated=False)


def test_time_limit_forgets_an_interval_that_does_not_come_back() -> None:
    """A fresh DBC run's burst of init_steps updates: one long interval without an evaluation
    (1200 s), then short ones (150 s) and one with an evaluation (400 s). The burst counts until the
    next interval of its kind replaces it; the one with an evaluation keeps counting after shorter
    ones, for any evaluation cadence."""
    clock = FakeClock()
    limit = TimeLimit(40.0, now=clock)  # 2400 s
    for t, evaluated, stop in ((1000.0, False, False),  # 1000 + 1000 by 2000
                               (1150.0, False, False),  # the burst forgotten: 1150 + 150
                               (1550.0, True, False),   # 1550 + 400 by 1950
                               (1700.0, False, False),  # 1700 + 400 by 2100
                               (2050.0, False, True)):  # 2050 + 400 would pass 2400, though 150 s would not
        clock.t = t
        assert limit.stop_after_checkpoint(evaluated=evaluated) is stop, t


def test_the_trainers_estimate_of_the_next_interval_counts_when_longer() -> None:
    """DBC's burst after intervals of random acting: 30 s intervals say nothing of it."""
    clock = FakeClock()
    limit = TimeLimit(30.0, now=clock)  # 1800 s
    clock.t = 60.0
    assert not limit.stop_after_checkpoint(evaluated=False, ahead_s=0.0)
    clock.t = 90.0  # 30 s interval; the trainer foresees 1500 s: 90 + 1500 < 1800
    assert not limit.stop_after_checkpoint(evaluated=False, ahead_s=1500.0)
    clock.t = 400.0  # 400 + 1500 > 1800, though 400 + 310 would not
    assert limit.stop_after_checkpoint(evaluated=False, ahead_s=1500.0)
    assert not limit.stop_after_checkpoint(evaluated=False, ahead_s=10.0)  # a shorter estimate: the last intervals
    assert limit.would_pass(1401.0) and not limit.would_pass(1399.0)


def test_an_interval_the_trainer_foretold_is_not_kept_once_over() -> None:
    """A sitting that resumed pixel DBC before its burst: after the foretold 1500 s burst the
    episodes take 30 s again, and the sitting goes on to its limit instead of stopping with an
    hour left (as it did while the burst counted as the last interval of its kind)."""
    clock = FakeClock()
    limit = TimeLimit(50.0, now=clock)  # 3000 s
    limit.mark(ahead_s=1500.0)  # the first interval is the burst: nothing measured before it
    clock.t = 1600.0  # 1600 + 1500 would pass 3000; the burst is over and none comes next
    assert not limit.stop_after_checkpoint(evaluated=False)
    for t in range(1630, 2951, 30):  # 30 s episodes: from 2950 the next ends by 2980, within 3000
        clock.t = float(t)
        assert not limit.stop_after_checkpoint(evaluated=False), t
    clock.t = 2980.0  # the next would end at 3010
    assert limit.stop_after_checkpoint(evaluated=False)


def test_no_limit_never_stops() -> None:
    clock = FakeClock()
    limit = TimeLimit(0.0, now=clock)
    clock.t = 1e9
    assert not limit.stop_after_checkpoint(evaluated=True, ahead_s=1e9) and not limit.would_pass(1e9)


def test_negative_time_limit_is_refused_naming_the_key(runs_dir: Path) -> None:
    with pytest.raises(ConfigError, match="time_limit_min"):
        compose_preset("mountaincar_ppo", runs_dir, "time_limit_min=-1")


def test_time_limit_changes_neither_hash_nor_run_dir(runs_dir: Path) -> None:
    plain = compose_preset("mountaincar_ppo", runs_dir)
    limited = compose_preset("mountaincar_ppo", runs_dir, "time_limit_min=30")
    assert limited.time_limit_min == 30 and config_hash(limited) == config_hash(plain)
    plans = [plan_profile("smoke", str(runs_dir), ["mountaincar_ppo"], overrides=o)
             for o in ((), ("time_limit_min=30",))]
    dirs = [[t.run_dir for p in plan for t in p.trials] for plan in plans]
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
