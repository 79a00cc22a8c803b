"""Scale-out through Hydra's own launchers: joblib for local parallel trials, submitit for SLURM."""
from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

import pytest

from plls_bench.core.atomic_files import read_jsonl
from plls_bench.rundirs.run_dir import Run
from tests.conftest import run_cli, start_cli


def statuses(runs: Path) -> list[str]:
    paths = sorted(runs.glob("mountaincar_data/default/seed=*/status.json"))
    return [json.loads(p.read_text())["state"] for p in paths]


LAUNCHERS = {
    "submitit_local": ["hydra/launcher=submitit_local", "hydra.launcher.timeout_min=5"],
    "joblib": ["hydra/launcher=parallel", "torch_threads=1"],
}


@pytest.mark.slow
@pytest.mark.parametrize("launcher", sorted(LAUNCHERS))
def test_two_job_multirun_completes(launcher: str, tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    done = run_cli("-m", "+experiment=mountaincar_data", "seed=0,1", f"runs_dir={runs}", "progress=false",
                   *LAUNCHERS[launcher])
    assert done.returncode == 0, done.stderr[-2000:]
    assert statuses(runs) == ["done", "done"]


def test_slurm_launcher_config_resolves(tmp_path: Path) -> None:
    done = run_cli("--cfg", "hydra", "+experiment=mountaincar_data", "hydra/launcher=slurm",
                   "hydra.launcher.partition=cpu", f"runs_dir={tmp_path}")
    assert done.returncode == 0, done.stderr
    assert "SlurmLauncher" in done.stdout and "partition: cpu" in done.stdout


def submitit_tasks(folder: Path) -> list[int]:
    """Pids of the submitit job processes (``python -m submitit.core._submit FOLDER/...``) under ``folder``."""
    pids = []
    for proc in Path("/proc").iterdir():
        try:
            args = (proc / "cmdline").read_bytes().decode(errors="replace").split("\0")
        except OSError:  # not a process, or one that just ended
            continue
        if "submitit.core._submit" in args and any(a.startswith(str(folder)) for a in args):
            pids.append(int(proc.name))
    return pids


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/cmdline").exists(), reason="finds the job's process through /proc")
def test_requeued_job_resumes_from_its_checkpoint(tmp_path: Path) -> None:
    """What SLURM + submitit do at a time limit (max_num_timeout): signal the job, which requeues
    itself with the same overrides; the trial resumes in the same run dir from its checkpoint.
    submitit_local runs the same machinery; the test sends the signal itself, after a checkpoint."""
    runs = tmp_path / "runs"
    run_dir = runs / "mountaincar_ppo" / "requeue" / "seed=0"
    proc = start_cli("-m", "+experiment=mountaincar_ppo", f"runs_dir={runs}", "progress=false", "variant=requeue",
                     "torch_threads=1", "budget.train_env_steps=5120", "budget.eval_every_env_steps=2560",
                     "hydra/launcher=submitit_local", "hydra.launcher.timeout_min=5")  # 10 iterations
    deadline = time.monotonic() + 120
    while len(read_jsonl(run_dir / "metrics" / "train.jsonl")) < 3:
        assert proc.poll() is None, f"launch ended early:\n{proc.stdout.read() if proc.stdout else ''}"
        assert time.monotonic() < deadline, "job made no progress"
        time.sleep(0.05)
    tasks = submitit_tasks(runs / ".submitit")
    assert len(tasks) == 1, tasks
    os.kill(tasks[0], signal.SIGUSR2)  # submitit's preemption / timeout signal (SUBMITIT_PREEMPT_SIGNAL)
    assert len(read_jsonl(run_dir / "metrics" / "train.jsonl")) < 10, "signalled mid-training"
    output, _ = proc.communicate(timeout=180)
    assert proc.returncode == 0, output[-3000:]
    logs = "".join(p.read_text() for p in (runs / ".submitit").rglob("*.out"))
    assert "Requeued job" in logs, "submitit requeued the job: " + logs[-2000:]
    iterations = [r["iteration"] for r in Run(run_dir).read_metrics("train")]
    assert iterations == list(range(1, 11)), "resumed from the checkpoint: no iteration lost or repeated"
    starts = json.loads((run_dir / "provenance.json").read_text())["starts"]
    assert len(starts) == 2, "the requeued job resumed the same run dir"
    assert (Run(run_dir).read_status() or {}).get("state") == "done"
