"""The main job end to end: ``reproduce --profile smoke`` runs every preset, films the policies
and renders every table and figure of the registry; a second run redoes nothing."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from plls_bench.pipeline.filming import filmed_presets
from plls_bench.pipeline.plan import list_presets
from plls_bench.pipeline.sweeps import load_sweep, sweep_names
from plls_bench.report.collect import IdStatus, verify_outputs
from plls_bench.report.registry import ENTRIES
from tests.test_reproduce import reproduce


@pytest.mark.slow
def test_smoke_profile_runs_every_preset_and_renders_every_id(tmp_path: Path) -> None:
    runs, out = tmp_path / "runs", tmp_path / "results"
    args = ("--profile", "smoke", "--runs", str(runs), "--out", str(out))
    first = reproduce(*args, timeout=3600)
    assert first.returncode == 0, (first.stdout + first.stderr)[-4000:]
    for preset in list_presets():
        assert f"[reproduce] {preset}: ok; ran 1 trial(s), 0 already done" in first.stdout
    index = json.loads((out / "index.json").read_text())
    statuses = {row["id"]: IdStatus(**row) for row in index["ids"]}
    assert list(statuses) == [entry.id for entry in ENTRIES]
    # every id has its runs; "partial" only for content a tiny budget lacks (Fig 14's grass frame)
    assert {i: s.status for i, s in statuses.items() if s.status not in ("ok", "partial")} == {}
    # a declared sweep's other values run only with `reproduce --sweep`, never in a profile: their
    # arms in a sweep figure have no trials here, every other curve has at least one
    sweep_only = {f"{sw.key.rsplit('.', 1)[-1]}={v}" for sw in map(load_sweep, sweep_names()) for v in sw.others}
    for s in (s for s in statuses.values() if s.kind == "figure"):
        ran = {arm: n for arm, n in s.trials.items() if arm not in sweep_only}
        assert ran and min(ran.values()) >= 1, (s.id, s.trials)
        assert all(s.trials[arm] == 0 for arm in s.trials.keys() & sweep_only), (s.id, s.trials)
    assert verify_outputs(out, statuses) == []
    readme = (out / "README.md").read_text()
    for entry in ENTRIES:
        assert f"{entry.kind}s/{entry.id}." in readme, f"{entry.id} is not in results/README.md"

    again = reproduce(*args, "--no-report", timeout=600)
    assert again.returncode == 0, again.stderr[-2000:]
    assert again.stdout.count("trial(s) already done\n") == len(list_presets())
    assert again.stdout.count("filmstrip already made\n") == len(filmed_presets())
