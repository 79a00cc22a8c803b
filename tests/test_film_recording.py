"""Filmstrips of trained policies (Figs 11, 19, 22): frames, steps, goal, the CLI on real runs."""
from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from plls_bench.core.atomic_files import read_json
from plls_bench.film.recording import filmstrip_config, record
from plls_bench.pipeline.execute import execute
from tests.conftest import REPO_ROOT, compose_preset


def pump(obs: np.ndarray) -> np.ndarray:
    """A hand-written MountainCar policy: push the way the car moves (energy pumping)."""
    return np.where(obs[:, 1:2] >= 0, 1.0, -1.0).astype(np.float32)


def pump_steps_to_goal(x: float, cap: int = 999) -> int:
    """Steps :func:`pump` needs from (x, 0) to the goal, by MountainCarContinuous-v0's equations
    (speed clipped to +-0.07, an inelastic left wall at -1.2, goal x >= 0.45 with v >= 0)."""
    v = 0.0
    for steps in range(1, cap + 1):
        v = min(max(v + (1.0 if v >= 0 else -1.0) * 0.0015 - 0.0025 * math.cos(3 * x), -0.07), 0.07)
        x = max(x + v, -1.2)
        v = 0.0 if x == -1.2 and v < 0 else v
        x, v = float(np.float32(x)), float(np.float32(v))  # the env keeps its state in float32
        if x >= 0.45 and v >= 0:
            return steps
    raise AssertionError(f"the pumping policy did not reach the goal within {cap} steps")


def test_mountaincar_filmstrip_starts_at_the_papers_state_and_counts_steps_to_goal(tmp_path: Path) -> None:
    cfg = compose_preset("mountaincar_ppo", tmp_path)  # plain PPO: the policy's actions are the env's
    strip = filmstrip_config("mountaincar", [])
    rec = record(cfg, pump, strip)
    goal = pump_steps_to_goal(-0.5309)  # Fig. 11's s0
    assert rec.terminated and rec.length == goal
    assert rec.frame_steps == [*range(0, goal, 4), goal] and strip.interval == 4
    frames = np.stack(rec.frames)
    assert frames.shape == (len(rec.frame_steps), 200, 300, 3) and frames.dtype == np.uint8
    assert not np.array_equal(frames[0], frames[-1])  # the car moved
    assert rec.episode_return == pytest.approx(100 - 0.1 * goal)  # |a| = 1 each step, +100 at the goal


def test_a_step_cap_ends_the_strip_on_its_last_step(tmp_path: Path) -> None:
    cfg = compose_preset("mountaincar_ppo", tmp_path)
    rec = record(cfg, pump, filmstrip_config("mountaincar", ["interval=8"]), max_steps=10)
    assert rec.frame_steps == [0, 8, 10] and rec.length == 10 and not rec.terminated


def film(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "plls_bench.film", *args], cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=300)


@pytest.mark.slow
@pytest.mark.parametrize(("preset", "cap", "interval", "size"), [("mountaincar_plls_ppo", 0, 4, (200, 300)),
                                                                 ("carracing_plls_ppo", 100, 48, (200, 300)),
                                                                 ("cheetah_plls_dbc", 30, 40, (84, 84))])
def test_cli_films_a_policy_run(preset: str, cap: int, interval: int, size: tuple[int, int], tmp_path: Path) -> None:
    """Figs 11, 19 and 22 from smoke runs (CarRacing and cheetah capped), as conf/filmstrip/<env>.yaml
    sets them (docs/results.md, "Policy filmstrips")."""
    run_dir = tmp_path / "runs" / preset / "default" / "seed=0"
    cfg = compose_preset(preset, tmp_path / "runs")
    assert execute(cfg, run_dir) == "done"
    done = film(str(run_dir), *(["--max-steps", str(cap)] if cap else []))
    assert done.returncode == 0, done.stderr[-2000:]
    meta = read_json(run_dir / "filmstrip" / "filmstrip.json")
    with np.load(run_dir / "filmstrip" / "frames.npz") as npz:
        frames, steps = npz["frames"], npz["frame_steps"]
    frames_run = meta["episode_length"] * cfg.env.action_repeat  # frame steps count action repeat
    assert steps.tolist() == meta["frame_steps"] == sorted({*range(0, frames_run, interval), frames_run})
    assert frames.shape == (len(steps), *size, 3) and frames.dtype == np.uint8 and frames.std() > 0
    assert meta["interval"] == interval and meta["run_status"] == "done"
    assert meta["checkpoint"] == "dbc.pt" if cfg.runner == "dbc" else meta["checkpoint"].startswith("ppo-")
    assert np.isfinite(meta["episode_return"])
    assert meta["steps_to_goal"] == (meta["episode_length"] if preset.startswith("mountaincar") and meta["terminated"]
                                     else None)
    first = (run_dir / "filmstrip" / "frames.npz").read_bytes()
    again = film(str(run_dir), "--out", str(tmp_path / "again"), *(["--max-steps", str(cap)] if cap else []))
    assert again.returncode == 0 and (tmp_path / "again" / "frames.npz").read_bytes() == first  # deterministic


@pytest.mark.parametrize(("make", "message"), [
    (lambda d: d, "no readable config.json"),
    (lambda d: d / "nope", "no such run directory"),
])
def test_cli_refuses_what_is_not_a_policy_run(make, message: str, tmp_path: Path) -> None:
    done = film(str(make(tmp_path)))
    assert done.returncode == 2 and done.stderr.strip().splitlines() == [done.stderr.strip()]
    assert message in done.stderr and not (tmp_path / "filmstrip").exists()


def test_cli_refuses_a_run_without_a_policy_or_checkpoint(tmp_path: Path) -> None:
    study = compose_preset("mountaincar_onestep", tmp_path)
    from plls_bench.rundirs.run_dir import Run, config_hash

    Run(tmp_path / "study").prepare(study, config_hash(study))
    ppo = compose_preset("mountaincar_ppo", tmp_path)
    Run(tmp_path / "ppo").prepare(ppo, config_hash(ppo))  # started, no checkpoint yet
    for name, message in (("study", "runner 'study' has no policy to film"), ("ppo", "no committed checkpoint")):
        done = film(str(tmp_path / name))
        assert done.returncode == 2 and message in done.stderr, done.stderr
        assert not (tmp_path / name / "filmstrip").exists()
    bad = film(str(tmp_path / "ppo"), "interval=0")
    assert bad.returncode == 2 and "filmstrip.interval" in bad.stderr
    after = film(str(tmp_path / "ppo"), "--out", str(tmp_path / "strip"), "interval=0")  # settings after an option
    assert after.returncode == 2 and "filmstrip.interval" in after.stderr, after.stderr


def test_reproduce_films_a_done_run_once_per_strip(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """Which presets are filmed comes from conf/filmstrip; a strip made of the same done run with
    the same settings (its done marker, or an older strip's filmstrip.json) is not made again."""
    from plls_bench.pipeline import filming
    from plls_bench.pipeline.plan import plan_profile
    from plls_bench.rundirs.run_dir import Run, config_hash

    commands: list[list[str]] = []
    monkeypatch.setattr(filming.subprocess, "run",
                        lambda cmd: commands.append(cmd) or subprocess.CompletedProcess(cmd, 0))
    plans = plan_profile("smoke", str(tmp_path / "runs"), ["mountaincar_plls_ppo", "mountaincar_ppo"], rates={})
    trial = next(p for p in plans if p.experiment == "mountaincar_plls_ppo").trials[0]
    assert filming.film_policies(plans) == [] and commands == []  # not done yet; plain PPO is never filmed
    assert "mountaincar_plls_ppo: no filmstrip, no done trial holds a policy (seed=0 first)" in capsys.readouterr().out
    run_hash = config_hash(trial.cfg)
    Run(trial.run_dir).write_status("done", config_hash=run_hash)
    assert filming.film_policies(plans) == [] and commands == []  # done, but no checkpoint to film
    _fake_checkpoint(trial.run_dir)
    assert filming.film_policies(plans) == [] and len(commands) == 1 and str(trial.run_dir) in commands[0]

    strip, output = filmstrip_config("mountaincar"), Run(trial.run_dir).output("filmstrip")
    meta = {"settings": strip.settings(), "max_steps": trial.cfg.budget.eval_max_steps or None,
            "run_config_hash": run_hash, "run_status": "done"}
    output.write(strip.output_hash(run_hash, "done", trial.cfg.budget.eval_max_steps), {"filmstrip.json": meta})
    (output.path / "done.json").unlink()  # as a strip written before done markers: read from filmstrip.json
    for made in (True, False):
        capsys.readouterr()
        assert filming.film_policies(plans) == []
        assert ("filmstrip already made" in capsys.readouterr().out) is made and len(commands) == 2 - made
        output.write("another strip", {"filmstrip.json": {**meta, "settings": {**meta["settings"], "interval": 8}}})


def _fake_checkpoint(run_dir: Path) -> None:
    """A PPO checkpoint's commit point (``latest.json``): what tells the plan a run holds a policy."""
    (run_dir / "checkpoints").mkdir(parents=True, exist_ok=True)
    (run_dir / "checkpoints" / "latest.json").write_text(json.dumps({"model": "ppo-0000001.zip",
                                                                     "progress": {"iteration": 1}}))


def test_reproduce_films_the_first_done_trial_that_holds_a_policy(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A record exported before records carried checkpoints (seed 0 here) has no policy: the next
    done seed with one is filmed, from its record when its run dir is gone."""
    from plls_bench.pipeline import filming
    from plls_bench.pipeline.plan import plan_profile
    from plls_bench.rundirs.record_layout import record_path
    from plls_bench.rundirs.run_dir import Run, config_hash

    commands: list[list[str]] = []
    monkeypatch.setattr(filming.subprocess, "run",
                        lambda cmd: commands.append(cmd) or subprocess.CompletedProcess(cmd, 0))
    plan = plan_profile("quick", str(tmp_path / "runs"), ["mountaincar_plls_ppo"], rates={})[0]
    first, second = plan.trials[:2]
    Run(first.run_dir).write_status("done", config_hash=config_hash(first.cfg))  # done, no checkpoint
    record = record_path(second.run_dir)
    Run(record).write_status("done", config_hash=config_hash(second.cfg))
    _fake_checkpoint(record)
    second = dataclasses.replace(second, recorded=True)
    plan = dataclasses.replace(plan, trials=[first, second, *plan.trials[2:]])
    assert filming.film_policies([plan]) == [] and len(commands) == 1 and str(record) in commands[0]
