"""The run-directory contract: atomic files, tolerant jsonl, status, resume, superseding."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from plls_bench.core.atomic_files import atomic_write_json, jsonl_line, read_jsonl
from plls_bench.pipeline.execute import execute
from plls_bench.rundirs.composition import CONF_DIR, recorded_config
from plls_bench.rundirs.run_dir import (
    VARIANT_EXCLUDED_KEYS,
    Run,
    config_hash,
    iter_run_dirs,
    unhashed_keys,
    variant_name,
)
from tests.conftest import compose_preset


def test_atomic_write_leaves_no_temp_files(tmp_path: Path) -> None:
    atomic_write_json(tmp_path / "a.json", {"x": 1})
    atomic_write_json(tmp_path / "a.json", {"x": 2})
    assert json.loads((tmp_path / "a.json").read_text()) == {"x": 2}
    assert [p.name for p in tmp_path.iterdir()] == ["a.json"]


def test_jsonl_reader_skips_a_torn_last_line(tmp_path: Path) -> None:
    run = Run(tmp_path)
    run.log("eval", {"step": 1})
    run.log("eval", {"step": 2})
    with open(run.metrics_path("eval"), "a") as handle:
        handle.write('{"step": 3, "ret')  # killed mid-write
    assert [r["step"] for r in read_jsonl(run.metrics_path("eval"))] == [1, 2]


def test_truncate_drops_rows_after_the_checkpoint(tmp_path: Path) -> None:
    run = Run(tmp_path)
    for step in range(5):
        run.log("eval", {"step": step})
    assert run.truncate_metrics("eval", lambda r: r["step"] <= 2) == 2
    assert [r["step"] for r in run.read_metrics("eval")] == [0, 1, 2]


def test_appended_rewritten_and_truncated_streams_share_one_line_format(tmp_path: Path) -> None:
    run, row = Run(tmp_path), {"b": np.float32(0.5), "a": 1}
    run.log("appended", row)
    run.write_metrics("written", [row])
    run.truncate_metrics("appended", lambda r: True)
    line = jsonl_line(row)
    assert line == '{"a": 1, "b": 0.5}\n'
    assert run.metrics_path("appended").read_text() == run.metrics_path("written").read_text() == line


def test_a_run_output_is_made_only_once_every_file_and_its_marker_are_written(tmp_path: Path,
                                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    strip = Run(tmp_path).output("filmstrip")
    assert strip.path == tmp_path / "filmstrip" and not strip.is_made("h1")
    strip.write("h1", {"frames.npz": b"npz", "filmstrip.json": {"interval": 4}})
    assert strip.is_made("h1") and not strip.is_made("h2")
    assert (strip.path / "frames.npz").read_bytes() == b"npz"
    assert json.loads((strip.path / "filmstrip.json").read_text()) == {"interval": 4}
    assert sorted(p.name for p in strip.path.iterdir()) == ["done.json", "filmstrip.json", "frames.npz"]

    def torn(path: Path, data: bytes) -> None:  # the second file's write is killed
        if path.name == "filmstrip.json":
            raise KeyboardInterrupt
        path.write_bytes(data)

    # bytes directly, and under atomic_write_json
    for module in ("plls_bench.rundirs.run_dir", "plls_bench.core.atomic_files"):
        monkeypatch.setattr(f"{module}.atomic_write_bytes", torn)
    with pytest.raises(KeyboardInterrupt):
        strip.write("h2", {"frames.npz": b"new", "filmstrip.json": {"interval": 8}})
    assert not strip.is_made("h1") and not strip.is_made("h2")  # half old, half new: made with neither
    with pytest.raises(KeyError, match="not a declared run output"):
        Run(tmp_path).output("videos")


def test_a_run_output_without_a_marker_is_read_through_its_legacy_hash(tmp_path: Path) -> None:
    strip = Run(tmp_path).output("filmstrip")
    atomic_write_json(strip.path / "filmstrip.json", {"hash": "old"})  # written before markers
    legacy = lambda path: json.loads((path / "filmstrip.json").read_text())["hash"]  # noqa: E731
    assert strip.is_made("old", legacy) and not strip.is_made("new", legacy) and not strip.is_made("old")


def test_variant_names() -> None:
    assert variant_name("auto", "") == "default"
    assert variant_name("auto", "repr/state=none,seed=3") == "repr.state=none,seed=3"
    assert variant_name("ne8", "whatever") == "ne8"


def test_execute_writes_the_contract_and_skips_when_done(runs_dir: Path) -> None:
    cfg = compose_preset("mountaincar_data", runs_dir)
    run_dir = runs_dir / "mountaincar_data" / "default" / "seed=0"
    assert execute(cfg, run_dir) == "done"
    for name in ("config.json", "provenance.json", "status.json", "metrics/dataset.json"):
        assert (run_dir / name).is_file(), name
    status = json.loads((run_dir / "status.json").read_text())
    assert status["state"] == "done"
    provenance = json.loads((run_dir / "provenance.json").read_text())
    assert {"git_sha", "git_dirty", "packages", "command", "host", "device", "start_time"} <= set(provenance)
    assert {"gymnasium", "box2d", "envpool", "mujoco", "dm-control"} <= set(provenance["packages"])  # every simulator
    assert provenance["packages"]["envpool"] is not None  # installed by pyproject.toml
    assert execute(cfg, run_dir) == "skipped"
    assert list(iter_run_dirs(runs_dir)) == [run_dir]


def test_changed_config_moves_the_old_run_aside(runs_dir: Path) -> None:
    run_dir = runs_dir / "x" / "default" / "seed=0"
    execute(compose_preset("mountaincar_data", runs_dir), run_dir)
    changed = compose_preset("mountaincar_data", runs_dir, "budget.data_episodes=3")
    assert execute(changed, run_dir) == "done"
    superseded = list((runs_dir / ".superseded").rglob("config.json"))
    assert len(superseded) == 1, "the old run is kept, not overwritten"
    assert json.loads((run_dir / "config.json").read_text())["config"]["budget"]["data_episodes"] == 3


def test_adding_trials_leaves_finished_trials_done(runs_dir: Path) -> None:
    """The trial count is the plan's: seed k's run is the same experiment at 3 or 10 trials, and a
    run dir that wrote its hash before that rule (budget.trials hashed) is still identified."""
    run_dir = runs_dir / "mountaincar_data" / "default" / "seed=0"
    three = compose_preset("mountaincar_data", runs_dir, "budget.trials=3")
    assert execute(three, run_dir) == "done"
    ten = compose_preset("mountaincar_data", runs_dir, "budget.trials=10")
    assert config_hash(ten) == config_hash(three)
    stored = json.loads((run_dir / "config.json").read_text())
    old_rule_hash = "0123456789abcdef"  # what a hash that still held budget.trials wrote
    atomic_write_json(run_dir / "config.json", {**stored, "config_hash": old_rule_hash})
    atomic_write_json(run_dir / "status.json", {"state": "done", "config_hash": old_rule_hash})
    assert Run(run_dir).is_done(config_hash(ten))
    assert execute(ten, run_dir) == "skipped"
    other = compose_preset("mountaincar_data", runs_dir, "budget.data_episodes=3")
    assert not Run(run_dir).is_done(config_hash(other)), "a key that changes the run still tells runs apart"


def test_failed_run_records_the_error(runs_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import plls_bench.data as data

    def explode(cfg, run):
        raise RuntimeError("boom")

    monkeypatch.setattr(data, "run", explode)
    run_dir = runs_dir / "e" / "default" / "seed=0"
    with pytest.raises(RuntimeError):
        execute(compose_preset("mountaincar_data", runs_dir), run_dir)
    status = json.loads((run_dir / "status.json").read_text())
    assert status["state"] == "failed" and "boom" in status["error"]


def test_the_variant_name_leaves_out_exactly_the_keys_that_change_no_result() -> None:
    """Hydra reads exclude_keys from yaml, so it cannot import rundirs/run_dir.py: the two must agree."""
    hydra_cfg = yaml.safe_load((CONF_DIR / "config.yaml").read_text())["hydra"]
    excluded = hydra_cfg["job"]["config"]["override_dirname"]["exclude_keys"]
    want = {*VARIANT_EXCLUDED_KEYS, *unhashed_keys()}
    assert len(excluded) == len(set(excluded)) and set(excluded) == want, (
        "conf/config.yaml hydra.job.config.override_dirname.exclude_keys must list "
        f"{sorted(want)} (plls_bench/rundirs/run_dir.py: VARIANT_EXCLUDED_KEYS and unhashed_keys()); "
        f"got {sorted(excluded)}. "
        "A key that changes no result goes into rundirs/run_dir.py's HASH_* tables first, then into that list.")


def test_a_recorded_config_reads_where_the_run_lives_now(tmp_path: Path) -> None:
    """Both policy loaders (PPO's load_trained, DBC's load_trained_agent) read configs this way."""
    cfg = compose_preset("mountaincar_ppo", tmp_path / "elsewhere")
    moved = tmp_path / "records" / "mountaincar_ppo" / "default" / "seed=0"
    Run(moved).prepare(cfg, config_hash(cfg))
    assert recorded_config(moved).runs_dir == str(tmp_path / "records")
    with pytest.raises(FileNotFoundError, match="config.json is missing: not a run directory"):
        recorded_config(tmp_path / "empty")
