"""Shared fixtures: every test composes the shipped configs and writes under a temp runs_dir."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from plls_bench.composition import compose
from plls_bench.config import Config

REPO_ROOT = Path(__file__).resolve().parent.parent
EXPERIMENTS = sorted(p.stem for p in (REPO_ROOT / "conf" / "experiment").glob("*.yaml"))


@pytest.fixture
def runs_dir(tmp_path: Path) -> Path:
    return tmp_path / "runs"


@pytest.fixture
def one_torch_thread():
    """torch on one thread for the test: small networks gain nothing from threads, and on a busy
    2-core machine torch's threads spin-wait (a 10x slowdown measured here)."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def compose_preset(experiment: str | None, runs_dir: Path, *overrides: str) -> Config:
    """The shipped preset at smoke budget (unless overridden), writing under ``runs_dir``."""
    base = [f"+experiment={experiment}"] if experiment else []
    return compose([*base, "budget=smoke", f"runs_dir={runs_dir}", "progress=false", *overrides])


def run_cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    """``python -m plls_bench ARGS`` in the repo root, as a user would run it."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.run([sys.executable, "-m", "plls_bench", *args], cwd=REPO_ROOT, env=env,
                          capture_output=True, text=True, timeout=timeout)
