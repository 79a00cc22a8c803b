"""reproduce.sh's orchestration: the plan, done-trial accounting, and interrupted runs finishing."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from plls_bench.pipeline.execute import execute
from plls_bench.pipeline.plan import list_presets, plan_profile
from plls_bench.pipeline.rates import rate_machines
from plls_bench.reproduce import records_line
from tests.conftest import REPO_ROOT, UNWRITABLE, compose_preset, unwritable_path, unwritable_reason

MC = ["mountaincar_data", "mountaincar_va", "mountaincar_ppo"]


def reproduce(*args: str, timeout: float = 900) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "plls_bench.reproduce", *args], cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=timeout)


def start_reproduce(*args: str) -> subprocess.Popen[str]:
    """reproduce in its own process group, as a terminal would run it (Ctrl-C reaches every job)."""
    # A shell's background job (`pytest ... &`) starts with SIGINT ignored, and children inherit
    # that; restore the default so Ctrl-C reaches reproduce as it would from a terminal.
    return subprocess.Popen([sys.executable, "-m", "plls_bench.reproduce", *args], cwd=REPO_ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True, preexec_fn=_default_sigint)


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def wait_for_state(status: Path, state: str, timeout: float = 300) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if json.loads(status.read_text())["state"] == state:
                return
        except (OSError, ValueError, KeyError):
            pass
        time.sleep(0.05)
    raise AssertionError(f"{status} never reached {state!r}")


def test_dry_run_prints_the_whole_paper_plan_and_runs_nothing(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    done = reproduce("--profile", "paper", "--dry-run", "--runs", str(runs))
    assert done.returncode == 0, done.stderr
    for preset in list_presets():
        assert preset in done.stdout
    assert "CPU-hours" in done.stdout and "trials to run" in done.stdout
    assert "rates measured on " in done.stdout and "; this machine: " in done.stdout  # the estimate's basis
    assert not runs.exists()


def test_rates_are_counted_by_the_cpu_that_measured_them(tmp_path: Path) -> None:
    path = tmp_path / "throughput.json"
    machines = ["vm: x86_64, AMD EPYC, 2 cores, load average 1, 1, 1; torch 2.13.0+cpu",
                "vm: x86_64, Intel(R) Xeon(R) Processor, 2 cores, load average 1, 1, 1; torch 2.13.0+cpu",
                "vm: x86_64, AMD EPYC, 2 cores, load average 2, 2, 2; torch 2.13.0+cpu",
                "vm: x86_64, 2 cores, load average 1, 1, 1; torch 2.13.0+cpu"]  # written before CPU names
    path.write_text(json.dumps({"rates": {f"k{i}": {"machine": m, "value": 1.0} for i, m in enumerate(machines)}}))
    assert rate_machines(path) == {"AMD EPYC": 2, "Intel(R) Xeon(R) Processor": 1, "an unnamed CPU": 1}
    assert rate_machines(tmp_path / "missing.json") == {}


def test_plan_counts_done_trials_and_orders_artifacts_first(runs_dir: Path) -> None:
    cfg = compose_preset("mountaincar_data", runs_dir)
    execute(cfg, runs_dir / "mountaincar_data" / "default" / "seed=0")
    plans = plan_profile("smoke", str(runs_dir), only=list(reversed(MC)), rates={})
    assert [p.experiment for p in plans] == MC  # data, then V_a, then the policy that uses them
    assert [len(p.pending) for p in plans] == [0, 1, 1]
    changed = plan_profile("quick", str(runs_dir), only=["mountaincar_data"], rates={})
    assert len(changed[0].pending) == 1, "a done run with another config is not done"


def test_unknown_preset_is_refused_before_anything_runs(tmp_path: Path) -> None:
    done = reproduce("--profile", "smoke", "--only", "nope", "--runs", str(tmp_path / "r"))
    assert done.returncode == 2 and "nope" in done.stderr
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("kind", UNWRITABLE)
@pytest.mark.parametrize("option", ["--runs", "--out"])
def test_a_path_that_cannot_be_written_is_refused_before_any_launch(option: str, kind: str, tmp_path: Path) -> None:
    bad, runs = unwritable_path(kind, tmp_path), tmp_path / "runs"
    paths = {"--runs": str(runs), "--out": str(tmp_path / "out"), option: str(bad)}
    done = reproduce("--profile", "smoke", "--only", "mountaincar_data", *(x for kv in paths.items() for x in kv))
    assert done.returncode == 2, done.stdout + done.stderr
    assert done.stderr.strip().splitlines() == [f"reproduce: {option}: cannot create or write {bad}: {bad.parent} "
                                                f"{unwritable_reason(kind, bad)}"]
    assert done.stdout == "" and not runs.exists() and not (tmp_path / "out").exists(), "nothing planned or run"


def clone_of_this_tree(dest: Path) -> Path:
    """A fresh git clone of this checkout with its uncommitted changes committed on top, so the
    clone runs exactly the code under test; ``.venv`` is linked, as a worktree links it."""
    git = ["git", "-c", "user.name=test", "-c", "user.email=test@localhost"]
    subprocess.run([*git, "clone", "-q", str(REPO_ROOT), str(dest)], check=True)
    listed = subprocess.run(["git", "-C", str(REPO_ROOT), "ls-files", "-z", "--modified", "--deleted", "--others",
                             "--exclude-standard"], check=True, capture_output=True, text=True).stdout
    for name in filter(None, set(listed.split("\0"))):
        source, target = REPO_ROOT / name, dest / name
        if source.is_file():
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(source.read_bytes())
        else:
            target.unlink(missing_ok=True)
    subprocess.run([*git, "-C", str(dest), "add", "-A"], check=True)
    subprocess.run([*git, "-C", str(dest), "commit", "-q", "--allow-empty", "-m", "uncommitted changes"], check=True)
    (dest / ".venv").symlink_to(REPO_ROOT / ".venv")
    return dest


@pytest.mark.slow
def test_a_smoke_reproduce_leaves_git_status_empty(tmp_path: Path) -> None:
    """The README's main command, default paths, in a fresh clone: run dirs and the smoke
    collector's output land in git-ignored places, the committed results/ is untouched."""
    clone = clone_of_this_tree(tmp_path / "clone")
    done = subprocess.run([sys.executable, "-m", "plls_bench.reproduce", "--profile", "smoke", "--only",
                           "mountaincar_data"], cwd=clone, env={**os.environ, "PYTHONPATH": str(clone)},
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert (clone / "results" / "runs" / "mountaincar_data" / "default" / "seed=0" / "status.json").is_file()
    assert (clone / "results" / "smoke" / "README.md").is_file(), "the smoke collector wrote results/smoke"
    status = subprocess.run(["git", "-C", str(clone), "status", "--porcelain"], capture_output=True, text=True)
    assert status.returncode == 0 and status.stdout == ""


@pytest.mark.slow
@pytest.mark.parametrize("launcher", [[], ["--launcher", "joblib", "--jobs", "2"]], ids=["local", "joblib"])
def test_sigint_then_rerun_finishes_without_redoing_finished_runs(launcher: list[str], tmp_path: Path) -> None:
    runs, args = tmp_path / "runs", ["--profile", "smoke", "--only", *MC, "--no-report", *launcher]
    proc = start_reproduce(*args, "--runs", str(runs))
    wait_for_state(runs / "mountaincar_va" / "default" / "seed=0" / "status.json", "running")
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C: reproduce and the running job both get it
    output, _ = proc.communicate(timeout=120)
    assert proc.returncode == 130, output
    assert "interrupted" in output
    again = reproduce(*args, "--runs", str(runs))
    assert again.returncode == 0, again.stdout + again.stderr
    assert "mountaincar_data: all 1 trial(s) already done" in again.stdout
    assert "mountaincar_va: ok; ran 1 trial(s)" in again.stdout
    third = reproduce(*args, "--runs", str(runs))
    assert third.stdout.count("trial(s) already done\n") == len(MC), third.stdout


@pytest.mark.slow
def test_sigterm_to_reproduce_alone_stops_its_trials_then_a_rerun_finishes(tmp_path: Path) -> None:
    """A scheduler or `kill PID` signals reproduce, not its trials: reproduce passes SIGTERM on, the
    running trial writes status stopped, reproduce exits 143 and the same command finishes."""
    runs, args = tmp_path / "runs", ["--profile", "smoke", "--only", *MC, "--no-report", "--launcher", "joblib"]
    proc = start_reproduce(*args, "--runs", str(runs))
    # the PPO trial, the longest of the three at smoke budget (seconds): V_a's smoke training can end
    # within the second below on a fast machine, and a signal to a finished trial tests nothing
    status = runs / "mountaincar_ppo" / "default" / "seed=0" / "status.json"
    wait_for_state(status, "running")
    time.sleep(1.0)  # into the runner's own SIGTERM handling, installed right after "running" is written
    proc.send_signal(signal.SIGTERM)  # reproduce's pid only, not its process group
    output, _ = proc.communicate(timeout=120)
    assert proc.returncode == 143 and "terminated by signal SIGTERM" in output, output
    assert json.loads(status.read_text())["state"] == "stopped"
    again = reproduce(*args, "--runs", str(runs))
    assert again.returncode == 0, again.stdout + again.stderr
    assert "mountaincar_ppo: ok; ran 1 trial(s)" in again.stdout


@pytest.mark.slow
def test_sigkill_of_a_worker_then_rerun_completes(tmp_path: Path) -> None:
    runs, args = tmp_path / "runs", ["--profile", "smoke", "--only", *MC, "--no-report"]
    proc = start_reproduce(*args, "--runs", str(runs))
    status = runs / "mountaincar_ppo" / "default" / "seed=0" / "status.json"
    wait_for_state(status, "running")
    worker = _job_pid("+experiment=mountaincar_ppo", str(runs))
    os.kill(worker, signal.SIGKILL)
    output, _ = proc.communicate(timeout=120)
    assert proc.returncode == 1 and "failed presets: mountaincar_ppo" in output, output
    again = reproduce(*args, "--runs", str(runs))
    assert again.returncode == 0, again.stdout + again.stderr
    assert again.stdout.count("trial(s) already done\n") == 2  # data and V_a are not redone
    assert "mountaincar_ppo: ok; ran 1 trial(s), 0 already done" in again.stdout
    assert json.loads(status.read_text())["state"] == "done"
    starts = json.loads((status.parent / "provenance.json").read_text())["starts"]
    assert len(starts) == 2, "the killed trial resumed in its own run dir"


def _job_pid(*needles: str) -> int:
    """PID of the ``python -m plls_bench`` job whose command line holds every needle."""
    for proc_dir in Path("/proc").iterdir():
        if not proc_dir.name.isdigit():
            continue
        try:
            cmdline = (proc_dir / "cmdline").read_bytes().decode(errors="replace").split("\0")
        except OSError:
            continue
        if "plls_bench" in cmdline and all(any(n in part for part in cmdline) for n in needles):
            return int(proc_dir.name)
    raise AssertionError(f"no job with {needles}")


def test_a_runs_dir_elsewhere_is_told_the_checkout_s_records_go_unread(tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """Records are read beside --runs: a runs dir on a cluster's scratch would rebuild every
    recorded trial, so the launch says so and how to count them (a link beside it)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "results" / "records").mkdir(parents=True)
    scratch = tmp_path / "scratch" / "runs"
    line = records_line(str(scratch))
    assert "records: none at" in line and "results/records are not read" in line, line
    assert f"ln -s {tmp_path / 'results' / 'records'} {tmp_path / 'scratch' / 'records'}" in line
    (tmp_path / "scratch").mkdir()
    (tmp_path / "scratch" / "records").symlink_to(tmp_path / "results" / "records")
    assert "count as done" in records_line(str(scratch))
    assert "count as done" in records_line("results/runs")
    (tmp_path / "results" / "records").rmdir()
    assert "not read" not in records_line(str(tmp_path / "elsewhere" / "runs")), "no records in the checkout: no hint"
