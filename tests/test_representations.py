"""Representations are a visible setup step: runners build them through one call that logs the
artifact keys; everything else (env factories, filmstrips, load_trained) only loads, never trains."""
from __future__ import annotations

import logging
import re
import shlex
from pathlib import Path

import pytest

from plls_bench.film.recording import filmstrip_config, record
from plls_bench.repr.keys import repr_path
from plls_bench.repr.store import (
    MissingArtifact,
    Representations,
    ensure_representations,
    find_artifact,
    load_representations,
)
from plls_bench.rundirs.composition import compose
from plls_bench.train.ppo_model import build_vec_env
from tests.conftest import compose_preset


def hinted_command(message: str) -> list[str]:
    """The overrides of the ``python -m plls_bench ...`` command a MissingArtifact names."""
    found = re.search(r"`python -m plls_bench ([^`]*)`", message)
    assert found, message
    return shlex.split(found.group(1))


def test_load_only_path_names_the_missing_va_and_the_preset_that_builds_it(runs_dir: Path) -> None:
    cfg = compose_preset("mountaincar_plls_ppo", runs_dir, "seed=3")
    key = repr_path(cfg, "action").name
    with pytest.raises(MissingArtifact, match=rf"V_a artifact repr_action/{key} is missing") as err:
        load_representations(cfg)
    assert hinted_command(str(err.value)) == ["+experiment=mountaincar_va", "budget=smoke", f"runs_dir={runs_dir}"]
    with pytest.raises(MissingArtifact, match=key):  # a PL-LS env from the load-only path
        build_vec_env(cfg, 1, 0, load_representations(cfg))
    with pytest.raises(ValueError, match="repr.action.kind is 'vae' but V_a is not among"):
        build_vec_env(cfg, 1, 0)  # no models handed down: refused, not built
    with pytest.raises(MissingArtifact, match=key):  # a filmstrip of a run whose V_a is gone
        record(cfg, lambda obs: obs[:, :1], filmstrip_config("mountaincar", []))
    assert not any(runs_dir.glob("**/*")), "nothing trained or written"


def test_the_hinted_command_builds_exactly_the_missing_artifact(runs_dir: Path) -> None:
    cfg = compose_preset("mountaincar_plls_ppo", runs_dir, "data_seed=2", "seed=1")
    with pytest.raises(MissingArtifact) as err:
        load_representations(cfg)
    hint = compose(hinted_command(str(err.value)))
    assert hint.experiment == "mountaincar_va" and hint.data_seed == 2
    ensure_representations(hint)  # what running the hinted preset builds first
    loaded = load_representations(cfg)
    assert loaded.action_vae is not None and loaded.artifacts["action"].path == repr_path(cfg, "action")


def test_a_missing_vs_names_the_carracing_vs_preset(runs_dir: Path) -> None:
    cfg = compose_preset("carracing_plls_ppo", runs_dir)
    with pytest.raises(MissingArtifact, match=rf"V_s artifact repr_state/{repr_path(cfg, 'state').name}") as err:
        find_artifact(cfg, "state")
    assert hinted_command(str(err.value))[0] == "+experiment=carracing_vs"


def test_a_corrupt_artifact_is_not_rebuilt_by_the_load_only_path(runs_dir: Path) -> None:
    cfg = compose_preset("mountaincar_va", runs_dir)
    path = ensure_representations(cfg).artifacts["action"].path
    (path / "history.json").write_text("[]")
    with pytest.raises(MissingArtifact, match=r"is corrupt \(history.json does not match its checksum\)"):
        load_representations(cfg)
    assert (path / "history.json").read_text() == "[]", "left for the build step to discard and rebuild"


def test_ensure_representations_logs_which_artifacts_it_built_or_found(runs_dir: Path, caplog) -> None:
    cfg = compose_preset("mountaincar_va", runs_dir)
    key = repr_path(cfg, "action").name
    with caplog.at_level(logging.INFO, logger="plls_bench.repr.store"):
        first = ensure_representations(cfg)
        second = ensure_representations(cfg)
    lines = [r.getMessage() for r in caplog.records if r.name == "plls_bench.repr.store"]
    assert [line.split(",")[0] for line in lines] == [f"V_a artifact repr_action/{key} built",
                                                       f"V_a artifact repr_action/{key} found"]
    assert first.artifacts["action"].built and not second.artifacts["action"].built
    assert first.state_vae is None and first.action_bound == cfg.repr.action.latent_action_bound


def test_a_config_without_representations_needs_none_and_touches_nothing(runs_dir: Path) -> None:
    cfg = compose_preset("mountaincar_ppo", runs_dir)
    none = Representations(action_bound=cfg.repr.action.latent_action_bound)
    assert ensure_representations(cfg) == load_representations(cfg) == none
    assert not runs_dir.exists()
