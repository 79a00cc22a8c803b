"""retain_freed_memory: glibc keeps freed blocks in the heap, so reallocating reuses pages."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from plls_bench.core.malloc_retain import glibc_mallopt
from plls_bench.pipeline import execute as runner
from plls_bench.rundirs.run_dir import config_hash
from tests.conftest import REPO_ROOT, compose_preset

# A learner's update in miniature: a small conv net's forward and backward on one batch of
# frame stacks, whose activations (MiBs each, over glibc's mmap threshold) are allocated and freed
# at every update; prints the minor page faults of ten updates after ten warm-up ones.
UPDATES = """
import resource, sys, torch
from plls_bench.core.malloc_retain import retain_freed_memory
torch.set_num_threads(1)
if sys.argv[1] == "retain":
    assert retain_freed_memory()
else:  # glibc's own 128 KiB mmap threshold, fixed: its dynamic raise makes the default's faults vary by run
    from plls_bench.core.malloc_retain import glibc_mallopt
    assert glibc_mallopt()(-3, 128 * 1024) == 1  # M_MMAP_THRESHOLD
torch.manual_seed(0)
net = torch.nn.Sequential(torch.nn.Conv2d(9, 32, 3, stride=2), torch.nn.ReLU(), torch.nn.Conv2d(32, 32, 3),
                          torch.nn.Flatten(), torch.nn.Linear(32 * 39 * 39, 50))
frames = torch.rand(32, 9, 84, 84)
def update():
    net(frames).square().mean().backward()
for _ in range(10):
    update()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(10):
    update()
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(mode: str) -> int:
    done = subprocess.run([sys.executable, "-c", UPDATES, mode], cwd=REPO_ROOT, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return int(done.stdout.split()[-1])


@pytest.mark.skipif(glibc_mallopt() is None, reason="the C library is not glibc: the setting does nothing there")
def test_retained_memory_updates_without_page_faults() -> None:
    default, retained = _faults("default"), _faults("retain")
    assert default > 2000, default  # glibc's default maps fresh pages for the large blocks at every update
    assert retained < default / 20, (default, retained)  # retained, the heap's pages are reused


@pytest.mark.parametrize("setting", ["true", "false"])
def test_runner_applies_the_setting_and_the_hash_ignores_it(setting: str, runs_dir: Path,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[bool] = []
    monkeypatch.setattr(runner, "retain_freed_memory", lambda: calls.append(True) or True)
    # torch_threads=0: the test process's threads stay as they are
    cfg = compose_preset("mountaincar_ppo", runs_dir, f"retain_freed_memory={setting}", "torch_threads=0")
    runner._configure_process(cfg)
    assert calls == ([True] if setting == "true" else [])
    assert config_hash(cfg) == config_hash(compose_preset("mountaincar_ppo", runs_dir))


def test_a_non_boolean_setting_is_refused_naming_the_key(runs_dir: Path) -> None:
    with pytest.raises(Exception, match="retain_freed_memory"):
        compose_preset("mountaincar_ppo", runs_dir, "retain_freed_memory=sometimes")
