"""reproduce's launching (plls_bench.launch): the joblib queue refills a core as soon as a trial
ends, across presets, and stages keep artifacts before the presets that read them."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from plls_bench import launch
from plls_bench.launch import run_queue
from plls_bench.plan import PresetPlan, Trial
from tests.conftest import REPO_ROOT


def waits_for(flag: Path) -> list[str]:
    """A command that exits 0 once ``flag`` exists, or 1 after 60 s without it."""
    code = ("import pathlib, sys, time\n"
            f"flag = pathlib.Path({str(flag)!r})\n"
            "end = time.monotonic() + 60\n"
            "while not flag.exists() and time.monotonic() < end: time.sleep(0.05)\n"
            "sys.exit(0 if flag.exists() else 1)")
    return [sys.executable, "-c", code]


def touches(flag: Path, code: int = 0) -> list[str]:
    return [sys.executable, "-c", f"import pathlib, sys; pathlib.Path({str(flag)!r}).touch(); sys.exit({code})"]


def test_the_queue_starts_the_next_command_as_soon_as_a_slot_frees(tmp_path: Path) -> None:
    """Two slots: "first" waits for a flag that only the third command makes. The third starts when
    "second" ends, while "first" still runs; a queue that waited for both of its first two
    commands (one multirun of 2 jobs, then the next) would let "first" time out."""
    flag = tmp_path / "go"
    commands = [("first", waits_for(flag)), ("second", [sys.executable, "-c", "pass"]),
                ("third", touches(flag, code=3))]
    assert run_queue(commands, jobs=2) == {"first": 0, "second": 0, "third": 3}


def test_one_slot_runs_the_commands_in_order(tmp_path: Path) -> None:
    flag = tmp_path / "go"
    assert run_queue([("make", touches(flag)), ("wait", waits_for(flag))], jobs=1) == {"make": 0, "wait": 0}


@pytest.mark.slow
def test_joblib_reproduce_runs_the_stages_in_order(tmp_path: Path) -> None:
    """The dataset preset (stage 0) is reported done before V_a's (stage 1), which reads it."""
    runs = tmp_path / "runs"
    done = subprocess.run([sys.executable, "-m", "plls_bench.reproduce", "--profile", "smoke", "--only",
                           "mountaincar_data", "mountaincar_va", "--launcher", "joblib", "--jobs", "2",
                           "--no-report", "--runs", str(runs)], cwd=REPO_ROOT, capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    lines = [line for line in done.stdout.splitlines() if ": ok; ran 1 trial(s)" in line]
    assert [line.split()[1] for line in lines] == ["mountaincar_data:", "mountaincar_va:"], done.stdout
    for preset in ("mountaincar_data", "mountaincar_va"):
        status = json.loads((runs / preset / "default" / "seed=0" / "status.json").read_text())
        assert status["state"] == "done"


def test_the_queue_takes_resuming_trials_first_least_left_first(tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """Trials that resume from a checkpoint end (and can be recorded) soonest; fresh ones follow in
    plan order."""
    def trial(seed: int, at: int) -> Trial:
        return Trial(seed, tmp_path / f"seed={seed}", done=False, cfg=None, resumes_at=at, iterations=64,
                     resumes_from="run dir" if at else "")

    plans = [PresetPlan("a", "carracing", "ppo", [trial(0, 0), trial(1, 7)], 1024),
             PresetPlan("b", "carracing", "ppo", [trial(0, 0), trial(1, 30)], 1024)]
    launched: list[object] = []

    def fake_queue(commands: list[tuple[object, list[str]]], jobs: int) -> dict[object, int]:
        launched.extend(key for key, _ in commands)
        return {key: 0 for key, _ in commands}

    monkeypatch.setattr(launch, "run_queue", fake_queue)
    assert launch.run_plans(plans, "quick", str(tmp_path), [], jobs=2, per_trial=True) == []
    assert launched == [(1, 1), (0, 1), (0, 0), (1, 0)]  # (plan, seed): b at 30/64, a at 7/64, then a, b fresh
