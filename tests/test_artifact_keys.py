"""The committed V_s and V_a are the ones today's presets ask for: a config key that cannot change a
task's data (``env.visuals`` outside dm_control) stays out of its dataset key, so adding such a key
never orphans the recorded artifacts and silently retrains them in the next trial."""
from __future__ import annotations

from pathlib import Path

import pytest

from plls_bench.data import dataset_key
from plls_bench.repr.keys import repr_path
from tests.conftest import REPO_ROOT, compose_preset

RECORDS = REPO_ROOT / "results" / "records"


@pytest.mark.parametrize(("experiment", "budget", "which"), [
    ("carracing_ppo_vs", "quick", "state"),  # V_s, shared by every CarRacing trial at this budget
    ("carracing_plls_ppo", "quick", "state"),
    ("carracing_plls_ppo", "quick", "action"),
    ("mountaincar_plls_ppo_gsde", "paper", "action"),
    ("mountaincar_plls_ppo", "paper", "action"),
])
def test_recorded_representations_are_found_by_today_s_presets(experiment: str, budget: str, which: str) -> None:
    cfg = compose_preset(experiment, RECORDS, f"budget={budget}", "seed=4")
    path = repr_path(cfg, which)
    assert (path / "model.pt").is_file(), f"{experiment} at {budget} asks for {which} {path.name}, not in {RECORDS}"


def test_visuals_is_in_the_dataset_key_only_where_it_restyles(tmp_path: Path) -> None:
    for experiment in ("carracing_plls_ppo", "mountaincar_plls_ppo"):
        assert "visuals" not in dataset_key(compose_preset(experiment, tmp_path))["env"]
    stock = dataset_key(compose_preset("cheetah_plls_dbc", tmp_path))
    restyled = dataset_key(compose_preset("cheetah_plls_dbc", tmp_path, "env.visuals=dbc_reference"))
    assert stock["env"]["visuals"] == "stock" and stock != restyled
