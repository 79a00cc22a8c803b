"""Where a run came from: code version, packages, command, machine and time."""
from __future__ import annotations

import importlib.metadata
import os
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from plls_bench.rundirs.devices import cpu_model, device_name, resolve_device

# Every simulator a run can step is here: records of one preset made on two machines (a CPU
# campaign, a lent GPU) are comparable only where these versions agree.
PACKAGES = ("plls-bench", "torch", "numpy", "gymnasium", "stable-baselines3", "mujoco",
            "dm-control", "envpool", "hydra-core", "omegaconf", "box2d", "cvxpy")
REPO_ROOT = Path(__file__).resolve().parents[2]
SOURCE_SHA_VAR = "PLLS_BENCH_SOURCE_SHA"  # read only where no git checkout is found (git_state)


def _git(repo: Path, *args: str) -> str | None:
    try:
        out = subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True,
                             timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip()


def git_state(repo: Path = REPO_ROOT, paths: tuple[str, ...] = (), ignore: tuple[str, ...] = ()) -> dict[str, Any]:
    """Commit sha and whether the working tree has uncommitted changes (None outside git, where
    ``$PLLS_BENCH_SOURCE_SHA``, if set, names the commit the code was copied from). With ``paths``:
    the last commit that changed them, and whether they have uncommitted changes, so a file built
    by that code names the same commit in every checkout of a later commit that left it alone.
    ``ignore``: folders whose changes do not make the tree dirty."""
    sha = (_git(repo, "log", "-1", "--format=%H", "--", *paths) if paths else _git(repo, "rev-parse", "HEAD")) or None
    if sha is None and os.environ.get(SOURCE_SHA_VAR):
        # A copy of the code without .git (a container, a cluster node's rsync): the launcher
        # names the commit it copied; the dirty flag stays unknown, and the record says whence.
        return {"git_sha": os.environ[SOURCE_SHA_VAR], "git_dirty": None, "git_sha_from": SOURCE_SHA_VAR}
    spec = [*(paths or ((".",) if ignore else ())), *(f":(exclude){folder}" for folder in ignore)]
    status = _git(repo, "status", "--porcelain", "--untracked-files=no", "--", *spec)
    return {"git_sha": sha, "git_dirty": None if status is None else bool(status)}


def package_versions() -> dict[str, str | None]:
    versions: dict[str, str | None] = {}
    for name in PACKAGES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def device_description() -> str:
    """The machine's accelerator (or CPU) in words, whatever device the run asked for."""
    try:
        import torch
    except ImportError:
        return "cpu (torch missing)"
    if torch.cuda.is_available():
        return f"cuda: {torch.cuda.get_device_name(0)}"
    return f"cpu: {cpu_model()}, {os.cpu_count()} cores"


def device_used(setting: str) -> dict[str, str]:
    """The device a ``device`` setting resolves to here (``cpu``, ``cuda:0``) and its hardware."""
    device = resolve_device(setting)
    return {"device_resolved": str(device), "device_name": device_name(device)}


def collect_provenance(device: str = "auto", precision: str = "fp32") -> dict[str, Any]:
    """This start's record; ``device`` and ``precision`` are the run's settings."""
    return {
        # results/ is evidence, not code: reproduce exports records into the checkout it runs from,
        # and that must not mark the next start of a campaign there as run from changed code
        **git_state(ignore=("results",)),
        "packages": package_versions(),
        "python": sys.version.split()[0],
        "command": [Path(sys.executable).name, *sys.argv],
        "host": socket.gethostname(),
        "device": device_description(),
        **device_used(device),
        "precision": precision,  # the conv trunks' (plls_bench/repr/pixel_trunk.py); everything else is fp32
        "mujoco_gl": os.environ.get("MUJOCO_GL"),
        "start_time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
