"""``device``: auto by default, one resolver, an absent GPU refused before any run dir, and
checkpoints that load onto whatever device is present. CPU only: a GPU is simulated where needed."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from plls_bench.__main__ import validate_command_line
from plls_bench.config import ConfigError
from plls_bench.core.atomic_files import read_json
from plls_bench.pipeline.execute import execute
from plls_bench.rundirs.composition import config_from_dict
from plls_bench.rundirs.devices import cpu_model, resolve_device
from plls_bench.rundirs.run_dir import HASH_EXCLUDED_KEYS, Run, config_dict, config_hash, stable_hash
from tests.conftest import compose_preset, run_cli


@pytest.fixture
def no_gpu(monkeypatch: pytest.MonkeyPatch) -> None:
    """This machine has no GPU, whatever the test machine really has."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)


@pytest.fixture
def saved_as_if_on_gpu(monkeypatch: pytest.MonkeyPatch):
    """While active, torch.save tags every tensor ``cuda:0``, as a checkpoint written on a GPU
    machine: loading it without a ``map_location`` fails on a machine without one."""
    def activate() -> None:
        monkeypatch.setattr(torch.serialization, "location_tag", lambda storage: "cuda:0")
    return activate


def test_auto_is_the_default_and_resolves_to_cpu_without_a_gpu(no_gpu: None, runs_dir: Path) -> None:
    assert compose_preset("mountaincar_ppo", runs_dir).device == "auto"
    assert resolve_device("auto") == torch.device("cpu")
    assert resolve_device("cpu") == torch.device("cpu")


def test_cuda_without_a_gpu_is_refused_by_the_command_line(no_gpu: None, runs_dir: Path) -> None:
    with pytest.raises(ConfigError, match=r"^device: cuda was asked for"):
        validate_command_line(["+experiment=mountaincar_ppo", "device=cuda", f"runs_dir={runs_dir}"])
    validate_command_line(["+experiment=mountaincar_ppo", "device=auto", f"runs_dir={runs_dir}"])
    # SLURM jobs run on other nodes: they check their own device when they start
    validate_command_line(["-m", "hydra/launcher=slurm", "+experiment=mountaincar_ppo", "device=cuda",
                           f"runs_dir={runs_dir}"])
    cfg = compose_preset("mountaincar_ppo", runs_dir, "device=cuda")
    with pytest.raises(ConfigError, match=r"^device:"):
        execute(cfg, runs_dir / "job")
    assert not runs_dir.exists()


@pytest.mark.skipif(torch.cuda.is_available(), reason="device=cuda is valid on a machine with a GPU")
def test_cuda_without_a_gpu_exits_2_naming_device(runs_dir: Path) -> None:
    done = run_cli("+experiment=mountaincar_ppo", "device=cuda", f"runs_dir={runs_dir}")
    assert done.returncode == 2, done.stdout + done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "device" in lines[0], done.stderr
    assert not runs_dir.exists(), "a refused device must not create a run directory"


def test_a_run_recorded_on_a_gpu_machine_is_readable_here(no_gpu: None, runs_dir: Path) -> None:
    cfg = compose_preset("mountaincar_ppo", runs_dir, "device=cuda")
    assert config_from_dict(config_dict(cfg)).device == "cuda"


def test_device_does_not_change_the_config_hash_of_existing_runs(runs_dir: Path) -> None:
    """Runs recorded with the old default (device=cpu, hashed) keep their hash under auto."""
    old = config_dict(compose_preset("mountaincar_ppo", runs_dir, "device=cpu"))
    for key in ("use_sde", "sde_sample_freq", "normalize_obs", "normalize_reward"):  # newer than those runs
        del old["algo"]["ppo"][key]
    for key in ("backend", "backend_threads", "visuals"):  # env keys newer than those runs
        del old["env"][key]
    del old["precision"]  # newer than those runs too
    del old["budget"]["trials"]  # the plan's, never hashed since (runs.HASH_PLAN_KEYS; old records are re-hashed)
    old_hash = stable_hash({k: v for k, v in old.items() if k not in HASH_EXCLUDED_KEYS})
    for device in ("auto", "cpu", "cuda"):
        assert config_hash(compose_preset("mountaincar_ppo", runs_dir, f"device={device}")) == old_hash


def test_provenance_records_the_device_used(no_gpu: None, runs_dir: Path) -> None:
    cfg = compose_preset("mountaincar_ppo", runs_dir)
    Run(runs_dir / "r").prepare(cfg, config_hash(cfg))
    provenance = read_json(runs_dir / "r" / "provenance.json")
    assert provenance["device_resolved"] == "cpu" and provenance["device_name"]
    assert provenance["starts"][0]["device_resolved"] == "cpu"


def test_ppo_checkpoint_from_a_gpu_loads_on_cpu_with_auto(no_gpu: None, saved_as_if_on_gpu, runs_dir: Path) -> None:
    from plls_bench.train import checkpoint
    from plls_bench.train.ppo_model import build_vec_env, load_trained, new_model

    cfg = compose_preset("mountaincar_ppo", runs_dir)
    run = Run(runs_dir / "ppo")
    run.prepare(cfg, config_hash(cfg))
    venv = build_vec_env(cfg, 1, seed=0)
    model = new_model(cfg, venv)
    venv.close()
    assert model.device == torch.device("cpu")
    saved_as_if_on_gpu()
    checkpoint.save(run, model, checkpoint.Progress(1, 16, 0.0))
    loaded = load_trained(run.path).model  # device=auto
    assert loaded.device == torch.device("cpu")
    assert all(p.device.type == "cpu" for p in loaded.policy.parameters())
    with pytest.raises(ConfigError, match="device"):
        load_trained(run.path, device="cuda")


def test_dbc_checkpoint_from_a_gpu_loads_with_map_location(no_gpu: None, saved_as_if_on_gpu,
                                                           runs_dir: Path) -> None:
    from baselines.dbc import DBCAgent, FrameReplay
    from plls_bench.train.dbc_state import CHECKPOINT, Progress, load_checkpoint, save_checkpoint

    dbc = compose_preset("cheetah_dbc", runs_dir, "algo.dbc.hidden_dim=16", "algo.dbc.encoder_feature_dim=8",
                         "algo.dbc.model_hidden_dim=16").algo.dbc
    run = Run(runs_dir / "dbc")

    def fresh(seed: int) -> tuple[DBCAgent, FrameReplay]:
        torch.manual_seed(seed)
        return DBCAgent((17,), 6, dbc, resolve_device("auto")), FrameReplay((17,), 1, 6, 10, 5)

    agent, replay = fresh(0)
    saved_as_if_on_gpu()
    save_checkpoint(run, agent, replay, Progress(agent_steps=3), np.random.default_rng(0))
    with pytest.raises(RuntimeError, match="CUDA"):  # what a load without map_location does here
        torch.load(run.path / CHECKPOINT, weights_only=True)
    other, replay = fresh(1)
    progress = load_checkpoint(run, other, replay, np.random.default_rng(1))
    assert progress is not None and progress.agent_steps == 3
    for name, module in agent.modules().items():
        for a, b in zip(module.state_dict().values(), other.modules()[name].state_dict().values()):
            assert b.device.type == "cpu" and torch.equal(a, b), name


def test_a_copy_without_git_records_the_commit_its_launcher_names(tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """Outside a checkout the sha comes from $PLLS_BENCH_SOURCE_SHA, marked as such and never
    claimed clean; inside one the variable is ignored, so it cannot mask a dirty tree."""
    from plls_bench.rundirs.provenance import SOURCE_SHA_VAR, git_state

    monkeypatch.delenv(SOURCE_SHA_VAR, raising=False)
    assert git_state(tmp_path) == {"git_sha": None, "git_dirty": None}
    monkeypatch.setenv(SOURCE_SHA_VAR, "0123abc")
    assert git_state(tmp_path) == {"git_sha": "0123abc", "git_dirty": None, "git_sha_from": SOURCE_SHA_VAR}
    inside = git_state()
    assert inside["git_sha"] != "0123abc" and "git_sha_from" not in inside


def test_git_state_of_paths_names_the_last_commit_that_changed_them(tmp_path: Path) -> None:
    """What results/README.md names as its collector: the same commit in every checkout of a later
    commit that left the collector alone, and dirty only when the collector itself is."""
    import subprocess

    from plls_bench.rundirs.provenance import git_state

    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(tmp_path), "-c", "user.name=t", "-c", "user.email=t@t", *args],
                              check=True, capture_output=True, text=True).stdout.strip()

    git("init", "-q")
    for folder in ("code", "records"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "f.txt").write_text("1")
        git("add", folder)
        git("commit", "-qm", folder)
    first, head = git("rev-list", "--max-parents=0", "HEAD"), git("rev-parse", "HEAD")
    assert git_state(tmp_path, paths=("code",)) == {"git_sha": first, "git_dirty": False}
    assert git_state(tmp_path)["git_sha"] == head
    (tmp_path / "records" / "f.txt").write_text("2")
    assert git_state(tmp_path, paths=("code",))["git_dirty"] is False
    assert git_state(tmp_path)["git_dirty"] is True and git_state(tmp_path, ignore=("records",))["git_dirty"] is False
    (tmp_path / "code" / "f.txt").write_text("2")
    assert git_state(tmp_path, paths=("code",))["git_dirty"] is True
    assert git_state(tmp_path, ignore=("records",)) == {"git_sha": head, "git_dirty": True}


ZEN1 = ("processor\t: 0\nvendor_id\t: AuthenticAMD\ncpu family\t: 23\nmodel\t\t: 1\n"
        "model name\t: AMD EPYC\nflags\t\t: fpu sse4_2 avx avx2\n\n")
ZEN4 = ZEN1.replace("23", "25").replace("model\t\t: 1", "model\t\t: 17").replace("avx2", "avx2 avx512f avx512_bf16")


def test_cpu_model_tells_apart_machines_that_share_a_name() -> None:
    """Two VMs both named "AMD EPYC" trained the Cheetah CNN 4x apart: the description says why,
    from the first processor's block only, and without commas (machine lines are split on them)."""
    assert cpu_model(ZEN1 + ZEN4) == "AMD EPYC (family 23 model 1; AVX2)"
    assert cpu_model(ZEN4) == "AMD EPYC (family 25 model 17; AVX-512)"
    assert "," not in cpu_model(ZEN4)
    assert cpu_model("model name\t: Some CPU\n") == "Some CPU"
