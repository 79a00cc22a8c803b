"""Shared fixtures: every test composes the shipped configs and writes under a temp runs_dir."""
from __future__ import annotations

import dataclasses
import multiprocessing as mp
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from plls_bench.config import Config
from plls_bench.rundirs.composition import compose

REPO_ROOT = Path(__file__).resolve().parent.parent
EXPERIMENTS = sorted(p.stem for p in (REPO_ROOT / "conf" / "experiment").glob("*.yaml"))


@pytest.fixture
def runs_dir(tmp_path: Path) -> Path:
    return tmp_path / "runs"


@pytest.fixture
def dbc_carried(monkeypatch: pytest.MonkeyPatch) -> None:
    """The DBC runner's stopped runs carried as partial records, as exports did before
    ``RunnerSpec.snapshot_holds_replay``: for the runner-agnostic carrying (snapshots, parts, the
    whole-record cap) at small sizes, and the restore of partial records written then."""
    from plls_bench.pipeline.runner_registry import RUNNERS

    monkeypatch.setitem(RUNNERS, "dbc", dataclasses.replace(RUNNERS["dbc"], snapshot_holds_replay=False))


@pytest.fixture
def one_torch_thread():
    """torch on one thread for the test: small networks gain nothing from threads, and on a busy
    2-core machine torch's threads spin-wait (a 10x slowdown measured here)."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


UNWRITABLE = ("under_a_file", "read_only", "takes_no_entry")


def unwritable_path(kind: str, tmp_path: Path) -> Path:
    """A directory path this process cannot create: ``under_a_file`` (a regular file in the way),
    ``read_only`` (inside a directory it may not write) or ``takes_no_entry`` (in ``/proc``, which
    any mode check passes). As root, which CI and this machine's
    tests run as, mode bits do not stop writes (a chmod-0555 dir is writable), so the read-only case
    uses a read-only mount (``/proc/sys`` in a container), and is skipped where there is none."""
    if kind == "under_a_file":
        (tmp_path / "a_file").write_text("")
        return tmp_path / "a_file" / "runs"
    if kind == "takes_no_entry":  # /proc passes os.access as root but takes no new folder
        if creation_error(Path("/proc/plls-runs")) is None:
            pytest.skip("no /proc that refuses new entries on this system")
        return Path("/proc/plls-runs")
    if os.geteuid() != 0:
        locked = tmp_path / "read_only"
        locked.mkdir(mode=0o555)
        return locked / "runs"
    for mount in (Path("/proc/sys"), Path("/sys")):
        if mount.is_dir() and not os.access(mount, os.W_OK | os.X_OK):
            return mount / "plls-runs"
    pytest.skip("running as root with no read-only mount (/proc/sys, /sys) to stand for a read-only dir")


def creation_error(path: Path) -> str | None:
    """The error creating folder ``path`` gives (it is removed again if it was created), or None."""
    try:
        path.mkdir()
    except OSError as err:
        return err.strerror
    path.rmdir()
    return None


def unwritable_reason(kind: str, path: Path) -> str:
    """What the writable-dir check says of the nearest existing folder of ``unwritable_path(kind)``."""
    if kind == "takes_no_entry":
        return f"takes no new entry ({creation_error(path)})"
    return "is not a directory" if kind == "under_a_file" else "is not writable"


def compose_preset(experiment: str | None, runs_dir: Path, *overrides: str) -> Config:
    """The shipped preset at smoke budget (unless overridden), writing under ``runs_dir``."""
    base = [f"+experiment={experiment}"] if experiment else []
    return compose([*base, "budget=smoke", f"runs_dir={runs_dir}", "progress=false", *overrides])


def run_cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    """``python -m plls_bench ARGS`` in the repo root, as a user would run it."""
    return subprocess.run(cli_command(*args), cwd=REPO_ROOT, env=_cli_env(), capture_output=True,
                          text=True, timeout=timeout)


def start_cli(*args: str) -> subprocess.Popen[str]:
    """``python -m plls_bench ARGS`` started in the background (e.g. to kill it mid-run)."""
    return subprocess.Popen(cli_command(*args), cwd=REPO_ROOT, env=_cli_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def cli_command(*args: str) -> list[str]:
    return [sys.executable, "-m", "plls_bench", *args]


def _cli_env() -> dict[str, str]:
    return {**os.environ, "PYTHONUNBUFFERED": "1"}


def in_two_processes(target: Callable[..., None], *args: Any, timeout: float = 240) -> list[Any]:
    """Start ``target(*args, queue)`` in two spawned processes at once; return what each put on
    the queue (e.g. ``(artifact.built, str(artifact.path))``). Both must exit cleanly."""
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    procs = [ctx.Process(target=target, args=(*args, queue)) for _ in range(2)]
    for proc in procs:
        proc.start()
    results = [queue.get(timeout=timeout) for _ in procs]
    for proc in procs:
        proc.join(timeout=60)
        assert proc.exitcode == 0
    return results
