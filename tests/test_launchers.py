"""Scale-out through Hydra's own launchers: joblib for local parallel trials, submitit for SLURM."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.conftest import run_cli


def statuses(runs: Path) -> list[str]:
    return [json.loads(p.read_text())["state"] for p in sorted(runs.glob("mountaincar_data/default/seed=*/status.json"))]


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
