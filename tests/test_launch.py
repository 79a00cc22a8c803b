"""reproduce's launching (plls_bench.pipeline.launch): the joblib queue refills a core as soon as a trial
ends, across presets, and stages keep artifacts before the presets that read them."""
from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pytest

from plls_bench.pipeline import launch
from plls_bench.pipeline.launch import run_queue
from plls_bench.pipeline.plan import PresetPlan, Trial
from plls_bench.reproduce import format_plan
from plls_bench.rundirs.run_dir import STATUS_FAILED, STATUS_STOPPED, Run
from tests.conftest import REPO_ROOT, compose_preset


def waits_for(flag: Path) -> list[str]:
    """A command that exits 0 once ``flag`` exists, or 1 after 60 s without it."""
    code = ("import pathlib, sys, time\n"
            f"flag = pathlib.Path({str(flag)!r})\n"
            "end = time.monotonic() + 60\n"
            "while not flag.exists() and time.monotonic() < end: time.sleep(0.05)\n"
            "sys.exit(0 if flag.exists() else 1)")
    return [sys.executable, "-c", code]


def queued(commands: list[tuple[str, list[str]]]) -> list[tuple[str, launch.Launch]]:
    return [(key, lambda argv=argv: argv) for key, argv in commands]


def touches(flag: Path, code: int = 0) -> list[str]:
    return [sys.executable, "-c", f"import pathlib, sys; pathlib.Path({str(flag)!r}).touch(); sys.exit({code})"]


def test_the_queue_starts_the_next_command_as_soon_as_a_slot_frees(tmp_path: Path) -> None:
    """Two slots: "first" waits for a flag that only the third command makes. The third starts when
    "second" ends, while "first" still runs; a queue that waited for both of its first two
    commands (one multirun of 2 jobs, then the next) would let "first" time out."""
    flag = tmp_path / "go"
    commands = [("first", waits_for(flag)), ("second", [sys.executable, "-c", "pass"]),
                ("third", touches(flag, code=3))]
    assert run_queue(queued(commands), jobs=2) == {"first": 0, "second": 0, "third": 3}


def test_one_slot_runs_the_commands_in_order(tmp_path: Path) -> None:
    flag = tmp_path / "go"
    assert run_queue(queued([("make", touches(flag)), ("wait", waits_for(flag))]), jobs=1) == {"make": 0, "wait": 0}


def test_a_command_that_gives_no_argv_when_its_turn_comes_is_skipped(tmp_path: Path) -> None:
    flag = tmp_path / "made"
    commands = [("skipped", lambda: None), ("run", lambda: touches(flag))]
    assert run_queue(commands, jobs=1) == {"skipped": None, "run": 0} and flag.exists()


def test_a_trial_s_limit_is_the_time_left_to_the_deadline_when_it_starts(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(launch.time, "monotonic", lambda: 1000.0)
    assert launch._limit_at_start(0.0, None) == 0.0 and launch._limit_at_start(90.0, None) == 90.0
    assert launch._limit_at_start(0.0, 1000.0 + 600) == pytest.approx(10.0)  # 10 minutes left
    assert launch._limit_at_start(5.0, 1000.0 + 600) == 5.0  # its own limit is shorter
    assert launch._limit_at_start(0.0, 1000.0 + 60 * launch.MIN_START_MINUTES - 1) is None  # too late to start


@pytest.mark.slow
def test_joblib_reproduce_runs_the_stages_in_order(tmp_path: Path) -> None:
    """The dataset preset (stage 0) is reported done before V_a's (stage 1), which reads it; with a
    deadline each trial is launched with the time left as its time_limit_min."""
    runs = tmp_path / "runs"
    done = subprocess.run([sys.executable, "-m", "plls_bench.reproduce", "--profile", "smoke", "--only",
                           "mountaincar_data", "mountaincar_va", "--launcher", "joblib", "--jobs", "2",
                           "--stop-after-min", "60", "--no-report", "--runs", str(runs)], cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    lines = [line for line in done.stdout.splitlines() if ": ok; ran 1 trial(s)" in line]
    assert [line.split()[1] for line in lines] == ["mountaincar_data:", "mountaincar_va:"], done.stdout
    for preset in ("mountaincar_data", "mountaincar_va"):
        run_dir = runs / preset / "default" / "seed=0"
        assert json.loads((run_dir / "status.json").read_text())["state"] == "done"
        limits = [o for o in (run_dir / ".hydra" / "overrides.yaml").read_text().split() if "time_limit_min=" in o]
        assert len(limits) == 1 and 50 < float(limits[0].split("=")[1]) <= 60, limits


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

    def fake_queue(commands: list[tuple[object, launch.Launch]], jobs: int) -> dict[object, int]:
        launched.extend(key for key, _ in commands)
        return {key: 0 for key, _ in commands}

    monkeypatch.setattr(launch, "run_queue", fake_queue)
    assert launch.run_plans(plans, "quick", str(tmp_path), [], jobs=2, per_trial=True) == []
    assert launched == [(1, 1), (0, 1), (0, 0), (1, 0)]  # (plan, seed): b at 30/64, a at 7/64, then a, b fresh


def test_stop_after_min_starts_no_trial_too_close_to_the_deadline(tmp_path: Path) -> None:
    """With less than MIN_START_MINUTES given, the trial is reported not started and nothing runs."""
    runs = tmp_path / "runs"
    done = subprocess.run([sys.executable, "-m", "plls_bench.reproduce", "--profile", "smoke", "--only",
                           "mountaincar_data", "--stop-after-min", "1", "--no-report", "--runs", str(runs)],
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert "mountaincar_data: ok; ran 0 trial(s), 0 already done" in done.stdout
    assert "1 not started (--stop-after-min reached" in done.stdout
    assert not (runs / "mountaincar_data").exists()


def test_stop_after_min_is_refused_for_slurm(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "plls_bench.reproduce", "--launcher", "slurm", "--stop-after-min",
                           "60", "--dry-run", "--runs", str(tmp_path)], cwd=REPO_ROOT, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 2 and "--stop-after-min: SLURM starts jobs" in done.stderr


def test_the_wall_estimate_follows_the_queue_not_the_average(tmp_path: Path) -> None:
    """Two slots, trials of 2 s and 3 s left (resuming) and a fresh one of 10 s, as state SAC's
    three seeds stood: the queue starts the short ones first, so the 10 s trial starts at 2 s and the
    queue ends at 12 s, not at (2 + 3 + 10) / 2. A later stage starts when the earlier one ends."""
    def trial(seed: int, at: int) -> Trial:
        return Trial(seed, tmp_path / f"seed={seed}", done=False, cfg=None, resumes_at=at, iterations=10,
                     resumes_from="run dir" if at else "")

    sac = PresetPlan("sac", "cheetah", "dbc", [trial(0, 8), trial(1, 7), trial(2, 0)], 100,
                     trial_seconds={0: 2.0, 1: 3.0, 2: 10.0})
    assert launch.estimated_wall_seconds([sac], jobs=2) == pytest.approx(12.0)
    assert launch.estimated_wall_seconds([sac], jobs=1) == pytest.approx(15.0)
    assert launch.estimated_wall_seconds([sac], jobs=3) == pytest.approx(10.0)
    data = PresetPlan("data", "cheetah", "collect", [trial(0, 0)], 0, trial_seconds={0: 4.0})
    assert launch.estimated_wall_seconds([data, sac], jobs=2) == pytest.approx(16.0)


def test_the_local_launcher_s_estimates_count_a_learner_s_torch_threads(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The local launcher leaves pixel DBC at torch's default threads (one per core), so on 2 cores
    its 10 CPU-seconds take 5 wall seconds; under joblib each trial gets one thread, and a preset
    that sets one thread (MountainCar PPO) or a runner that is no learner (collection) keeps its
    CPU seconds as wall seconds. The time a trial needs left to start before a deadline (its
    first checkpoint) is counted the same way."""
    monkeypatch.setattr(launch.os, "cpu_count", lambda: 2)
    def plan(experiment: str, runner: str, seconds: float) -> PresetPlan:
        cfg = compose_preset(experiment, tmp_path)
        return PresetPlan(experiment, cfg.env.name, runner, [Trial(0, tmp_path / experiment, done=False, cfg=cfg)],
                          100, trial_seconds={0: seconds})

    dbc, ppo = plan("cheetah_dbc", "dbc", 10.0), plan("mountaincar_ppo", "ppo", 10.0)
    assert (dbc.trials[0].cfg.torch_threads, ppo.trials[0].cfg.torch_threads) == (0, 1)
    assert launch.estimated_wall_seconds([dbc], jobs=1, launcher="local") == pytest.approx(5.0)
    assert launch.estimated_wall_seconds([dbc], jobs=1, launcher="joblib") == pytest.approx(10.0)
    assert launch.estimated_wall_seconds([ppo], jobs=1, launcher="local") == pytest.approx(10.0)
    collect = dataclasses.replace(dbc, runner="collect")
    assert launch.estimated_wall_seconds([collect], jobs=1, launcher="local") == pytest.approx(10.0)
    wall = "about 0.0 h wall with 1 parallel job(s) of up to 2 thread(s) each"
    assert wall in format_plan([dbc], 1, launcher="local")
    # its first checkpoint too: 600 CPU-seconds away are 5 minutes on 2 threads, 10 on one
    dbc.first_stop_seconds = {0: 600.0}
    assert launch.start_minutes(dbc, dbc.trials[0], "local") == pytest.approx(5.0)
    assert launch.start_minutes(dbc, dbc.trials[0], "joblib") == pytest.approx(10.0)
    assert "1 trial(s) end" in launch.deadline_outlook([dbc], 1, 6, launcher="local")[0]
    assert "1 do not start" in launch.deadline_outlook([dbc], 1, 6, launcher="joblib")[0]
    started: dict[str, bool] = {}  # and so does the queue itself, 6 minutes before its deadline
    for name in ("local", "joblib"):
        monkeypatch.setattr(launch, "run_queue", lambda commands, jobs, name=name: {
            key: started.setdefault(name, go() is not None) for key, go in commands})
        launch.run_plans([dbc], "quick", str(tmp_path), [], stop_after_min=6, launcher=name)
    assert started == {"local": True, "joblib": False}


def test_with_estimates_the_queue_takes_the_shortest_time_left_first(tmp_path: Path) -> None:
    """A stage of two presets: state SAC's seeds (0.7, 1.0 and 3.3 h left; seed 2 fresh) and three
    CNN PPO trials each 70% from their end but 7 h from it. The fraction left would start the PPO
    trials before SAC's fresh seed 2; the estimated time left starts seed 2 first."""
    def trial(seed: int, at: int, iterations: int) -> Trial:
        return Trial(seed, tmp_path / f"seed={seed}", done=False, cfg=None, resumes_at=at, iterations=iterations,
                     resumes_from="partial record" if at else "")

    sac = PresetPlan("sac", "cheetah", "dbc", [trial(0, 80, 100), trial(1, 70, 100), trial(2, 0, 100)], 100,
                     trial_seconds={0: 0.7, 1: 1.0, 2: 3.3})
    ppo = PresetPlan("va", "carracing", "ppo", [trial(s, 19, 64) for s in range(3)], 1024,
                     trial_seconds={0: 7.0, 1: 7.0, 2: 7.0})
    assert [(i, t.seed) for i, t in launch.queue_order([ppo, sac])] == [(1, 0), (1, 1), (1, 2), (0, 0), (0, 1), (0, 2)]
    ppo.trial_seconds = {}  # no rate for one preset: the fraction of its own training left decides
    assert [(i, t.seed) for i, t in launch.queue_order([ppo, sac])] == [(1, 0), (1, 1), (0, 0), (0, 1), (0, 2), (1, 2)]


def test_the_dry_run_says_what_a_deadline_leaves(tmp_path: Path) -> None:
    """In units of MIN_START_MINUTES, 2 jobs and a deadline at 11: seeds 0 (2 left) and 1 (3 left)
    end, seed 2 (fresh, 10, started at 2) stops 90% through, seed 3 (fresh, 20, started at 3) 40%
    through. At 3.5, seed 3's turn comes less than one unit before the deadline: it never starts."""
    def trial(seed: int, at: int) -> Trial:
        return Trial(seed, tmp_path / f"seed={seed}", done=False, cfg=None, resumes_at=at, iterations=10,
                     resumes_from="run dir" if at else "")

    unit = 60.0 * launch.MIN_START_MINUTES  # seconds
    sac = PresetPlan("sac", "cheetah", "dbc", [trial(0, 8), trial(1, 7), trial(2, 0), trial(3, 0)], 100,
                     trial_seconds={0: 2 * unit, 1: 3 * unit, 2: 10 * unit, 3: 20 * unit})
    slots = launch.simulate_queue([sac], jobs=2)
    expected = [(0, 0, 2), (1, 0, 3), (2, 2, 12), (3, 3, 23)]  # (seed, start, end)
    assert [(s.trial.seed, s.start / unit, s.end / unit) for s in slots] == expected
    lines = launch.deadline_outlook([sac], jobs=2, stop_after_min=11 * launch.MIN_START_MINUTES)
    assert lines[0].startswith("by --stop-after-min")
    assert "2 trial(s) end, 2 stop at a checkpoint, 0 do not start" in lines[0]
    assert "sac seed=2 before about 90% of its training" in lines[1]
    assert "sac seed=3 before about 40% of its training" in lines[2]
    lines = launch.deadline_outlook([sac], jobs=2, stop_after_min=3.5 * launch.MIN_START_MINUTES)
    assert "2 trial(s) end, 1 stop at a checkpoint, 1 do not start" in lines[0] and len(lines) == 2
    sac.missing_rates = ["train/sac"]  # a rate never measured: no outlook rather than a wrong one
    assert launch.deadline_outlook([sac], jobs=2, stop_after_min=11)[0].endswith("some trials have no estimate")


def test_a_learner_starts_only_with_time_for_its_first_checkpoint(tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """CNN PPO seed 2 was started with 4.4 minutes left and a first iteration of about 9.5: it
    overran the deadline. With an estimate of its first checkpoint, the launch holds it back, and
    the dry run says so; without one, MIN_START_MINUTES still applies."""
    def trial(seed: int) -> Trial:
        return Trial(seed, tmp_path / f"seed={seed}", done=False, cfg=None, resumes_at=19, iterations=64,
                     resumes_from="partial record", checkpoints=45)

    ppo = PresetPlan("va", "carracing", "ppo", [trial(0), trial(1), trial(2)], 1024,
                     trial_seconds={s: 45 * 570.0 for s in range(3)},
                     first_stop_seconds={s: 570.0 for s in range(3)})
    assert launch.start_minutes(ppo, ppo.trials[0]) == pytest.approx(9.5)
    monkeypatch.setattr(launch.time, "monotonic", lambda: 1000.0)
    assert launch._limit_at_start(0.0, 1000.0 + 60 * 4.4, launch.start_minutes(ppo, ppo.trials[0])) is None
    assert launch._limit_at_start(0.0, 1000.0 + 60 * 10, launch.start_minutes(ppo, ppo.trials[0])) == pytest.approx(10)
    # 2 jobs: seeds 0 and 1 run their 45 iterations from 0, seed 2 starts when they end, 4.4 minutes
    # before the deadline
    minutes = (45 * 570.0 + 4.4 * 60) / 60
    assert "2 trial(s) end, 0 stop at a checkpoint, 1 do not start" in launch.deadline_outlook([ppo], 2, minutes)[0]
    ppo.first_stop_seconds = {}
    assert launch.start_minutes(ppo, ppo.trials[0]) == launch.MIN_START_MINUTES
    assert "2 trial(s) end, 1 stop at a checkpoint, 0 do not start" in launch.deadline_outlook([ppo], 2, minutes)[0]


def test_a_runner_without_checkpoints_starts_only_with_time_for_all_of_it(tmp_path: Path) -> None:
    """A collection of about 20 minutes runs to its end whatever its limit: with 10 minutes left
    it is held back, and the dry run says it does not start rather than that it stops."""
    data = PresetPlan("data", "mountaincar", "collect",
                      [Trial(0, tmp_path / "seed=0", done=False, cfg=None)], 0,
                      trial_seconds={0: 1200.0}, first_stop_seconds={0: 1200.0})
    assert launch.start_minutes(data, data.trials[0]) == pytest.approx(20)
    assert "0 trial(s) end, 0 stop at a checkpoint, 1 do not start" in launch.deadline_outlook([data], 1, 10)[0]
    assert "1 trial(s) end, 0 stop at a checkpoint, 0 do not start" in launch.deadline_outlook([data], 1, 21)[0]


def test_longest_first_ends_the_whole_queue_soonest(tmp_path: Path) -> None:
    """CarRacing V_a-only as it stood: 44, 34 and 22 CNN PPO iterations left. On 2 jobs the
    shortest-first queue runs 22 then 44 on one slot (66 iterations), longest-first 44 beside
    34 + 22 (56); ties keep plan order either way, and an unknown order is refused."""
    def trial(seed: int, at: int) -> Trial:
        return Trial(seed, tmp_path / f"seed={seed}", done=False, cfg=None, resumes_at=at, iterations=64,
                     resumes_from="partial record")

    va = PresetPlan("va", "carracing", "ppo", [trial(0, 42), trial(1, 30), trial(2, 20)], 1024,
                    trial_seconds={0: 22.0, 1: 34.0, 2: 44.0})
    assert [t.seed for _, t in launch.queue_order([va], "longest")] == [2, 1, 0]
    assert launch.estimated_wall_seconds([va], jobs=2) == pytest.approx(66.0)
    assert launch.estimated_wall_seconds([va], jobs=2, order="longest") == pytest.approx(56.0)
    va.trial_seconds = {}  # without estimates, the fraction left: the same order here
    assert [t.seed for _, t in launch.queue_order([va], "longest")] == [2, 1, 0]
    tied = PresetPlan("t", "carracing", "ppo", [trial(0, 0), trial(1, 0)], 1024, trial_seconds={0: 5.0, 1: 5.0})
    assert [t.seed for _, t in launch.queue_order([tied], "longest")] == [0, 1]
    with pytest.raises(ValueError, match="queue order 'random' is not one of shortest, longest"):
        launch.queue_order([va], "random")


def test_the_dry_run_names_the_queue_order(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "plls_bench.reproduce", "--profile", "smoke", "--only",
                           "mountaincar_ppo", "--queue-order", "longest", "--dry-run", "--runs", str(tmp_path)],
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "trials started in the launch queue's order (longest estimated time left first)" in done.stdout
    bad = subprocess.run([sys.executable, "-m", "plls_bench.reproduce", "--queue-order", "random", "--dry-run",
                          "--runs", str(tmp_path)], cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "--queue-order: invalid choice: 'random'" in bad.stderr


def test_a_trial_stopped_by_sigterm_is_not_a_failed_preset(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Exit 143 with status ``stopped`` (SIGTERM at a checkpoint) resumes at the next launch; exit
    143 with status ``failed``, or any exit of a trial that says nothing, is a failure."""
    trials = [Trial(seed, tmp_path / f"seed={seed}", done=False, cfg=None) for seed in range(3)]
    plan = PresetPlan("dbc", "cheetah", "dbc", trials, 100_000)
    Run(trials[0].run_dir).write_status(STATUS_STOPPED, reason="terminated by signal SIGTERM")
    assert launch._report(plan, [143, 0, None], 1.0) == []
    out = capsys.readouterr().out
    assert "dbc: ok; ran 2 trial(s)" in out and "seed(s) 0 stopped early" in out and "1 not started" in out
    Run(trials[1].run_dir).write_status(STATUS_FAILED, reason="boom")
    assert launch._report(plan, [143, 143, 0], 1.0) == ["dbc"]
    assert "FAILED (exit 143)" in capsys.readouterr().out
    assert launch._report(plan, [0, 0, 1], 1.0) == ["dbc"], "no status: a failure"
    assert launch._report(plan, [143], 1.0) == ["dbc"], "one code for the preset: not told apart"
