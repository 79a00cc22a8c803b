"""``reproduce --override KEY=VALUE``: an ablation of any config key, planned and costed beside the
presets' own runs, and every bad override refused before anything is planned or run."""
from __future__ import annotations

from pathlib import Path

import pytest

from plls_bench.config import ConfigError
from plls_bench.pipeline.overrides import override_variants
from plls_bench.pipeline.plan import plan_profile
from plls_bench.reproduce import format_plan, parse_args
from tests.test_reproduce import reproduce

PRESET = "mountaincar_plls_ppo"


def test_overrides_given_together_make_one_variant_and_a_sweep_one_per_value() -> None:
    assert override_variants([]) == []
    assert override_variants(["repr.action.latent_dim=8", "algo.ppo.n_epochs=5"]) == [
        ("repr.action.latent_dim=8", "algo.ppo.n_epochs=5")]
    assert override_variants(["repr.action.latent_dim=4,8"]) == [
        ("repr.action.latent_dim=4",), ("repr.action.latent_dim=8",)]


@pytest.mark.parametrize("override, says", [
    ("budget=quick", "budget is set by --profile"),
    ("budget.trials=5", "budget.trials is set by --profile"),
    ("seed=3", "seed is set by the profile's budget.trials"),
    ("runs_dir=/tmp/x", "runs_dir is set by --runs"),
    ("hydra.job.chdir=true", "hydra.job.chdir is set by --hydra"),
    ("torch_threads=2", "torch_threads changes no result"),
    ("repr.action.latent_dim", "--override takes KEY=VALUE, got 'repr.action.latent_dim'"),
])
def test_an_override_of_a_key_reproduce_sets_itself_is_refused(override: str, says: str) -> None:
    with pytest.raises(ConfigError, match=says.replace(".", r"\.")):
        override_variants([override])


def test_the_option_errors_name_the_flag_to_use(capsys: pytest.CaptureFixture[str]) -> None:
    for argv, says in ((["--hydra", "repr.action.latent_dim=8"], "a config key goes to --override KEY=VALUE"),
                       (["--sweep", "ne", "--override", "repr.action.latent_dim=8"], "--sweep and --override"),
                       (["--override", "seed=1"], "seed is set by")):
        with pytest.raises(SystemExit):
            parse_args(argv)
        assert says in capsys.readouterr().err


def test_plan_puts_each_variant_beside_the_presets_own_runs(tmp_path: Path) -> None:
    plans = plan_profile("smoke", str(tmp_path), only=[PRESET], rates={},
                         variants=override_variants(["repr.action.latent_dim=4,8"]))
    assert [p.label for p in plans] == [PRESET, f"{PRESET} repr.action.latent_dim=4",
                                        f"{PRESET} repr.action.latent_dim=8"]
    dirs = [p.trials[0].run_dir.relative_to(tmp_path).as_posix() for p in plans]
    assert dirs == [f"{PRESET}/default/seed=0", f"{PRESET}/repr.action.latent_dim=4/seed=0",
                    f"{PRESET}/repr.action.latent_dim=8/seed=0"]
    assert [p.trials[0].cfg.repr.action.latent_dim for p in plans[1:]] == [4, 8]
    assert not any(p.inert for p in plans)  # mountaincar_plls_ppo's V_a reads latent_dim


def test_an_override_of_a_representation_the_preset_has_off_is_planned_with_a_warning(tmp_path: Path) -> None:
    plans = plan_profile("smoke", str(tmp_path), only=["cheetah_sac_state"], rates={},
                         variants=override_variants(["repr.action.latent_dim=8"]))
    assert len(plans) == 2 and len(plans[1].trials) == len(plans[0].trials)  # still planned and run
    assert plans[1].inert == ["repr.action.latent_dim (V_a off)"] and plans[0].inert == []
    assert "warning: cheetah_sac_state repr.action.latent_dim=8: repr.action.latent_dim (V_a off): no module " \
           "of this preset reads it" in format_plan(plans, jobs=1)


def test_dry_run_costs_the_variants_and_an_unknown_key_is_refused_before_any_run_dir(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    dry = reproduce("--profile", "smoke", "--only", PRESET, "--override", "repr.action.latent_dim=4,8",
                    "--runs", str(runs), "--dry-run")
    assert dry.returncode == 0, dry.stderr
    for value in (4, 8):
        assert f"{PRESET} repr.action.latent_dim={value} " in dry.stdout
    assert "trials to run: 3 of 3" in dry.stdout and not runs.exists()
    bad = reproduce("--profile", "smoke", "--only", PRESET, "--override", "repr.action.nope=3", "--runs", str(runs))
    assert bad.returncode == 2 and "--override repr.action.nope=3 on mountaincar_plls_ppo" in bad.stderr
    assert "nope" in bad.stderr.splitlines()[-1] and not runs.exists()
