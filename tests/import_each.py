"""Import each named module in a process of its own: ``python -m tests.import_each MODULE...``.

Prints one JSON object, module -> traceback, for the modules that failed (``{}``: all imported).

A fresh interpreter per module costs about 2 CPU-seconds of torch alone, minutes for the whole
package on a small machine. So this process first imports the heavy third-party libraries (never
a module of ``plls_bench`` or ``baselines``; nor mujoco, dm_control or box2d, whose import depends
on what the suite sets up first), then forks one child per module: every child starts with no
project module loaded and imports just its own, as ``python -c "import MODULE"`` would.
"""
from __future__ import annotations

import importlib
import json
import os
import sys
import tempfile
import traceback
from pathlib import Path

PROJECT = ("plls_bench", "baselines")
PRELOAD = ("numpy", "scipy.stats", "pandas", "matplotlib.figure", "matplotlib.backends.backend_agg", "cv2",
           "cvxpy", "rliable.metrics", "torch", "gymnasium", "stable_baselines3", "hydra", "omegaconf", "tqdm")
WORKERS = 4


def _child(module: str, report: Path) -> None:
    """Runs in the forked child: import ``module``, write the traceback on failure, never return."""
    code = 0
    try:
        importlib.import_module(module)
    except BaseException:  # anything an import raises, SystemExit included, is a failure
        report.write_text(traceback.format_exc())
        code = 1
    os._exit(code)  # skip the parent's atexit handlers and buffers


def _reap(running: dict[int, tuple[str, Path]], failures: dict[str, str]) -> None:
    """Wait for one child and record its traceback if its import failed."""
    pid, status = os.wait()
    module, report = running.pop(pid)
    if os.waitstatus_to_exitcode(status) != 0:
        failures[module] = report.read_text() if report.exists() else f"died: wait status {status}"


def import_each(modules: list[str]) -> dict[str, str]:
    """Module -> traceback of those whose import failed in their own forked process."""
    for name in PRELOAD:
        importlib.import_module(name)
    loaded = sorted(m for m in sys.modules if m.split(".")[0] in PROJECT)
    if loaded:
        raise RuntimeError(f"project modules loaded before forking: {loaded}")
    failures: dict[str, str] = {}
    running: dict[int, tuple[str, Path]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for i, module in enumerate(modules):
            if len(running) >= WORKERS:
                _reap(running, failures)
            report = Path(tmp) / f"{i}.txt"
            sys.stdout.flush()  # a child must not inherit unflushed output
            pid = os.fork()
            if pid == 0:
                _child(module, report)
            running[pid] = (module, report)
        while running:
            _reap(running, failures)
    return failures


if __name__ == "__main__":
    print(json.dumps(import_each(sys.argv[1:])))
