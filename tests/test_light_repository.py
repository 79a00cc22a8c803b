"""A light repository: a finished record's PPO policy carries no optimiser state and still films and
evaluates as the full checkpoint; an unfinished trial is carried only while small; no tracked file
and not the records as a whole outgrow their caps (docs/results.md, "A light repository")."""
from __future__ import annotations

import subprocess
import zipfile
from io import BytesIO
from pathlib import Path

import pytest
import torch

from plls_bench.envs.evaluation import run_episodes
from plls_bench.film import film_run
from plls_bench.pipeline import record_export as export
from plls_bench.pipeline.execute import execute
from plls_bench.pipeline.record_export import REPLAY_NOT_CARRIED, export_records
from plls_bench.rundirs.record_layout import MAX_FILE_BYTES, PARTIAL_DIR, PENDING_DIR, RECORDS_BUDGET_BYTES
from plls_bench.rundirs.run_dir import run_dir_path
from plls_bench.train.checkpoint import OPTIMIZER_ENTRY, without_optimizer_state
from tests.conftest import REPO_ROOT, compose_preset
from tests.synthetic_runs import make_run

KEY = Path("default") / "seed=0"
RECORDS = "results/records"


def optimizer_state(zip_path: Path) -> dict:
    with zipfile.ZipFile(zip_path) as archive:
        return torch.load(BytesIO(archive.read(OPTIMIZER_ENTRY)), map_location="cpu", weights_only=True)


def tracked_sizes() -> dict[str, int]:
    """Every tracked file of the checkout with its size in bytes (what a clone holds)."""
    names = subprocess.run(["git", "ls-files", "-z"], cwd=REPO_ROOT, capture_output=True, text=True,
                           check=True).stdout.split("\0")
    return {name: (REPO_ROOT / name).stat().st_size for name in names if name and (REPO_ROOT / name).is_file()}


@pytest.mark.slow
def test_a_stripped_policy_films_and_evaluates_to_the_returns_of_the_full_checkpoint(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, one_torch_thread: None) -> None:
    from plls_bench.train.ppo_model import build_vec_env, load_trained

    monkeypatch.setattr(export, "EXCLUDED_BUDGETS", ())  # the smoke run stands in for a real one
    runs = tmp_path / "results" / "runs"
    cfg = compose_preset("mountaincar_ppo", runs)
    run_dir = run_dir_path(runs, "mountaincar_ppo", "default", 0)
    assert execute(cfg, run_dir) == "done"
    assert export_records(runs).written == ["mountaincar_ppo/default/seed=0"]
    record = tmp_path / "results" / "records" / "mountaincar_ppo" / KEY
    [full] = (run_dir / "checkpoints").glob("ppo-*.zip")
    stripped = record / "checkpoints" / full.name
    assert stripped.stat().st_size < full.stat().st_size
    assert optimizer_state(full)["state"] and optimizer_state(stripped)["state"] == {}, "Adam's moments are dropped"
    assert optimizer_state(stripped)["param_groups"] == optimizer_state(full)["param_groups"]

    returns = {}
    for name, source in (("full", run_dir), ("stripped", record)):
        trained = load_trained(source, "cpu")
        venv = build_vec_env(cfg, 2, seed=11, reprs=trained.reprs)
        returns[name] = run_episodes(venv, trained.act, 4, seed=11, max_steps=300)
        venv.close()
    assert returns["stripped"] == returns["full"]
    films = {name: film_run(source, tmp_path / name, device="cpu", max_steps=300)
             for name, source in (("full", run_dir), ("stripped", record))}
    assert films["stripped"]["episode_return"] == films["full"]["episode_return"]
    assert (tmp_path / "stripped" / "frames.npz").read_bytes() == (tmp_path / "full" / "frames.npz").read_bytes()


def test_committed_ppo_policies_carry_no_optimiser_state() -> None:
    zips = [REPO_ROOT / name for name in tracked_sizes() if name.startswith(f"{RECORDS}/") and name.endswith(".zip")
            and not name.startswith(f"{RECORDS}/{PARTIAL_DIR}/")]
    assert zips, "no committed PPO policy to check"
    heavy = [str(path.relative_to(REPO_ROOT)) for path in zips if optimizer_state(path)["state"]]
    assert not heavy, "finished records carry Adam's moments (re-export them):\n" + "\n".join(heavy)
    data = zips[0].read_bytes()
    assert without_optimizer_state(data) == data, "stripping is idempotent, so a re-export changes nothing"


def test_a_stopped_cnn_ppo_trial_is_carried_and_a_dbc_snapshot_is_not(tmp_path: Path) -> None:
    """At the real sizes: a CarRacing CNN PPO zip with Adam's moments (9.6 MiB) goes to a partial
    record; a state-SAC dbc.pt (45 MiB) stays behind, its metrics written as a pending record. A
    DBC-runner snapshot holds a replay buffer, so it is never carried, however small: pixel DBC,
    pixel SAC and state SAC alike leave only their metrics so far."""
    runs = tmp_path / "results" / "runs"
    ppo, _ = make_run(runs, "carracing_ppo", 0)
    ppo.log("eval", {"iteration": 0, "return_mean": 0.0})
    ppo.write_bytes("checkpoints/ppo-0000003.zip", b"w" * 10_062_095)
    ppo.write_json("checkpoints/latest.json", {"model": "ppo-0000003.zip", "normalization": None,
                                               "progress": {"iteration": 3}, "rng": {}})
    sizes = {"cheetah_sac_state": 45 * 2**20, "cheetah_dbc": 2**10, "cheetah_sac_pixel": 2**10}
    for experiment, size in sizes.items():
        run, _ = make_run(runs, experiment, 0)
        run.log("eval", {"iteration": 0, "return_mean": 0.0})
        run.write_bytes("checkpoints/replay/chunk_000000000000_000000000051.npz", b"r" * 1000)
        run.write_json("checkpoints/progress.json", {"iteration": 50, "agent_steps": 50, "replay_written": 51})
        run.write_bytes("checkpoints/dbc.pt", b"w" * size)
    done = export_records(runs)
    assert done.partial == ["carracing_ppo/default/seed=0"]
    assert sorted(done.pending) == sorted(f"{experiment}/default/seed=0" for experiment in sizes)
    assert sorted(done.skipped) == sorted(f"{experiment}/default/seed=0: status running ({REPLAY_NOT_CARRIED})"
                                          for experiment in sizes)
    records = tmp_path / "results" / "records"
    assert not [p for p in (records / PENDING_DIR).rglob("*") if p.is_file() and "checkpoints" in p.parts]
    assert sorted(p.name for p in (records / PARTIAL_DIR).iterdir()) == ["carracing_ppo"]


def test_no_tracked_file_and_not_the_records_outgrow_their_caps() -> None:
    sizes = tracked_sizes()
    over = [f"{name}: {size / 2**20:.1f} MiB" for name, size in sizes.items() if size > MAX_FILE_BYTES]
    assert not over, f"tracked files over {MAX_FILE_BYTES // 2**20} MiB:\n" + "\n".join(over)
    records = sum(size for name, size in sizes.items() if name.startswith(f"{RECORDS}/"))
    assert 0 < records <= RECORDS_BUDGET_BYTES, (
        f"{RECORDS} weighs {records / 2**20:.1f} MiB, over its budget of {RECORDS_BUDGET_BYTES // 2**20} MiB "
        "(plls_bench/rundirs/record_layout.py says what it is sized for)")
