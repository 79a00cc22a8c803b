"""The runner registry: every runner has a typed spec, and its own config checks in the config
layer's table under the same name (so validation, which composes every preset in test_config.py,
refuses a preset whose runner is unregistered or does not fit); every filmed preset names a
registered runner that fits; the registry imports no simulator."""
from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from plls_bench.config import ENV_NAMES, Config, ConfigError
from plls_bench.config.runner_checks import RUNNER_CHECKS
from plls_bench.pipeline.filming import filmed_presets
from plls_bench.pipeline.runner_registry import RUNNERS, SPECS, filming_runners, runner_spec
from plls_bench.rundirs.composition import filmstrip_config
from tests.conftest import REPO_ROOT, compose_preset


def _set(path: str, value: object) -> Callable[[Config], None]:
    """Set a dotted field of a composed (already validated) config, bypassing validation."""
    def apply(cfg: Config) -> None:
        *parents, leaf = path.split(".")
        node: object = cfg
        for part in parents:
            node = getattr(node, part)
        setattr(node, leaf, value)
    return apply


# runner -> (a preset it accepts, the Hydra override that breaks it, the same break on the object, the key named)
BAD_FOR_RUNNER: dict[str, tuple[str, str, Callable[[Config], None], str]] = {
    "collect": ("mountaincar_data", "algo=ppo", _set("algo.name", "ppo"), "algo"),
    "repr": ("mountaincar_va", "repr/action=none", _set("repr.action.kind", "none"), "repr"),
    "study": ("mountaincar_onestep", "repr/action=none", _set("repr.action.kind", "none"), "repr.action.kind"),
    "ppo": ("mountaincar_ppo", "algo.ppo.features_extractor=paper_cnn",
            _set("algo.ppo.features_extractor", "paper_cnn"), "algo.ppo.features_extractor"),
    "dbc": ("cheetah_dbc", "env.image_size=4", _set("env.image_size", 4), "env.image_size"),
}


def test_every_registered_runner_has_a_bad_config_case() -> None:
    assert set(BAD_FOR_RUNNER) == set(RUNNERS) == {spec.name for spec in SPECS}
    # config validation asks its own table (the config layer cannot import the registry): same names, same order
    assert tuple(RUNNER_CHECKS) == tuple(RUNNERS)
    # artifacts in stages of their own, in dependency order; the learners share the last stage
    artifact_stages = [spec.order for spec in SPECS if not spec.trains_policy]
    assert artifact_stages == list(range(len(artifact_stages)))
    assert {spec.order for spec in SPECS if spec.trains_policy} == {len(artifact_stages)}


@pytest.mark.parametrize("name", list(BAD_FOR_RUNNER))
def test_a_runners_own_validation_rejects_a_bad_config_naming_the_key(name: str, tmp_path: Path) -> None:
    preset, override, breaks, key = BAD_FOR_RUNNER[name]
    checks = RUNNER_CHECKS[name]
    cfg = compose_preset(preset, tmp_path)
    assert cfg.runner == name
    checks(cfg)  # the shipped preset passes its runner's checks
    breaks(cfg)
    with pytest.raises(ConfigError) as err:
        checks(cfg)
    message = str(err.value)
    assert message.splitlines() == [message] and message.startswith(f"{key}: "), message
    with pytest.raises(ConfigError) as composed:  # and composing it is refused by Config.validate
        compose_preset(preset, tmp_path, override)
    assert str(composed.value).startswith(f"{key}: ") and len(str(composed.value).splitlines()) == 1


def test_an_unregistered_runner_is_refused_naming_the_key(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"^runner: unknown value 'sac'; choose one of collect, repr"):
        compose_preset("mountaincar_ppo", tmp_path, "runner=sac")
    with pytest.raises(KeyError, match="not implemented"):
        runner_spec("sac")


def test_filmed_presets_are_declared_for_runners_with_a_policy(tmp_path: Path) -> None:
    """conf/filmstrip/<env>.yaml lists presets of that env whose runner's spec can load a policy,
    and exactly the presets the report's filmstrip figures show (Figs 11, 19, 22)."""
    from plls_bench.report.figures import images as fig_images
    from plls_bench.report.registry import ENTRIES

    for env in ENV_NAMES:
        for preset in filmstrip_config(env).presets:
            cfg = compose_preset(preset, tmp_path)
            assert cfg.env.name == env and cfg.runner in filming_runners(), preset
    shown = {e.sources[0].experiment for e in ENTRIES if e.build is fig_images.filmstrip}
    assert filmed_presets() == shown
    assert set(filming_runners()) == {"ppo", "dbc"}


def test_the_registry_and_config_validation_import_no_simulator_or_torch() -> None:
    code = ("import sys; from plls_bench.rundirs.composition import compose; "
            "import plls_bench.pipeline.runner_registry; import plls_bench.reproduce; "
            "compose(['+experiment=cheetah_plls_dbc']); "
            "print(sorted({m.split('.')[0] for m in sys.modules} & "
            "{'torch', 'gymnasium', 'dm_control', 'mujoco', 'cv2', 'stable_baselines3', 'matplotlib'}))")
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "[]", done.stdout + done.stderr


@pytest.mark.parametrize("name", list(RUNNERS))
def test_each_spec_loads_its_run_function(name: str) -> None:
    fn = runner_spec(name).load()
    assert callable(fn) and fn.__name__ == "run"


def test_a_spec_with_an_unknown_checkpoint_point_is_refused() -> None:
    """``checkpoints_at`` decides when the launch lets a learner start (plan._checkpoints_left): a
    typo would cost its trials as if they checkpointed every iteration."""
    spec = runner_spec("dbc")
    with pytest.raises(ValueError, match="checkpoints_at='episodes' is not one of iteration, episode"):
        type(spec)(spec.name, spec.load, order=spec.order, measure=spec.measure, checkpoints_at="episodes")
