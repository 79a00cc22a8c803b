"""algo=dbc is one source of the DBC reference (decisions D27): its clean-background launcher as run_all.sh
runs it for cheetah, action repeat included; the earlier mix (algo=dbc_mix) keeps the committed records'
config hashes; env/per_algo/ layers set env keys only."""
from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import pytest
import yaml

from plls_bench.config import EnvConfig
from plls_bench.core.atomic_files import read_json
from plls_bench.pipeline.plan import plan_profile
from plls_bench.rundirs.composition import CONF_DIR, compose
from plls_bench.rundirs.run_dir import STATUS_DONE, config_hash, stored_identity
from tests.conftest import REPO_ROOT, compose_preset

RECORDS = REPO_ROOT / "results" / "records"
PRESETS = ("cheetah_dbc", "cheetah_plls_dbc")


MIX = "algo=dbc_mix"  # the variant dir its records moved to when algo=dbc became the default


def recorded_trials() -> list[tuple[str, Path]]:
    """The committed done records of the DBC presets' mix variant, as (preset, record dir)."""
    found = []
    for preset in PRESETS:
        for record in sorted((RECORDS / preset / MIX).glob("seed=*")):
            if (read_json(record / "status.json") or {}).get("state") == STATUS_DONE:
                found.append((preset, record))
    return found


@pytest.mark.parametrize("preset", PRESETS)
def test_the_default_runs_at_the_launchers_action_repeat(preset: str, runs_dir: Path) -> None:
    """run_all.sh runs cheetah at action repeat 2; the README command, and so dbc_readme and the mix, at 4."""
    repeats = {algo: compose_preset(preset, runs_dir, *([f"algo={algo}"] if algo else [])).env.action_repeat
               for algo in ("", "dbc_mix", "dbc_readme")}
    assert repeats == {"": 2, "dbc_mix": 4, "dbc_readme": 4}
    assert compose_preset(preset, runs_dir, "env.action_repeat=3").env.action_repeat == 3, "the command line wins"


def test_the_mix_differs_from_the_default_in_the_action_repeat_alone(runs_dir: Path) -> None:
    default, mix = (compose_preset("cheetah_dbc", runs_dir, *extra) for extra in ((), ("algo=dbc_mix",)))
    assert mix.algo == default.algo and mix.budget == default.budget
    assert {f.name for f in fields(EnvConfig) if getattr(mix.env, f.name) != getattr(default.env, f.name)} == \
        {"action_repeat"}


def test_the_mix_keeps_the_hash_of_every_committed_dbc_record() -> None:
    """Each done record of cheetah_dbc / cheetah_plls_dbc composes back, with algo=dbc_mix at its own budget
    and seed, to the identity it was recorded with (its stored config re-hashed under today's rules, which
    is what counts a record done); under the new default it no longer does (it is rerun). Its dir is the
    one ``reproduce --override algo=dbc_mix`` plans, so that variant counts it done."""
    trials = recorded_trials()
    assert trials, f"no done records under {RECORDS}/cheetah_dbc/{MIX}"
    for preset, record in trials:
        written = read_json(record / "config.json")
        budget, seed = written["config"]["budget"]["name"], written["config"]["seed"]
        base = [f"+experiment={preset}", f"budget={budget}", f"seed={seed}"]
        identity = stored_identity(record)
        assert config_hash(compose([*base, "algo=dbc_mix"])) == identity, record
        assert config_hash(compose(base)) != identity, record


@pytest.mark.parametrize("preset", PRESETS)
def test_reproduce_counts_the_mix_records_done_for_their_variant_only(preset: str) -> None:
    recorded = {int(record.name.split("=")[1]) for p, record in recorded_trials() if p == preset}
    plans = plan_profile("quick", str(RECORDS.parent / "runs"), only=[preset], rates={}, variants=[(MIX,)])
    own, mix = (next(p for p in plans if p.overrides == overrides) for overrides in ((), (MIX,)))
    assert {t.seed for t in mix.trials if t.recorded} == recorded
    assert not any(t.recorded for t in own.trials), "the default (algo=dbc) has none of its own yet"


def test_env_per_algo_layers_set_only_env_keys() -> None:
    """An env/per_algo file is merged into the env node: it may hold env keys and nothing else."""
    allowed = {f.name for f in fields(EnvConfig)}
    paths = sorted((CONF_DIR / "env" / "per_algo").glob("*.yaml"))
    assert paths
    for path in paths:
        text = path.read_text()
        keys = set(yaml.safe_load(text) or {})
        assert "@package" not in text and keys and keys <= allowed, f"conf/env/per_algo/{path.name}: {sorted(keys)}"
