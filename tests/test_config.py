"""Every shipped yaml composes and validates; bad input fails before any run dir or compute."""
from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import pytest
import yaml

from plls_bench.config import BUDGET_NAMES, ENV_NAMES, BudgetConfig, ConfigError
from plls_bench.pipeline.sweeps import load_sweep
from plls_bench.rundirs.composition import CONF_DIR, compose
from tests.conftest import EXPERIMENTS, UNWRITABLE, run_cli, unwritable_path, unwritable_reason

# algo choices run by another runner on the env's state vector (state SAC: the DBC runner)
STATE_ALGOS = {"sac_state": ["runner=dbc", "env.pixels=false"]}
# algo choices of the DBC runner whose name does not start with dbc (pixel SAC: cheetah's pixels)
DBC_RUNNER_ALGOS = {**STATE_ALGOS, "sac_pixel": ["runner=dbc"]}


def overrides_for(yaml_path: Path) -> list[str]:
    """The group choices that make Hydra load ``yaml_path``; fails for a yaml no rule covers,
    so a new config directory cannot slip past this test."""
    rel = yaml_path.relative_to(CONF_DIR)
    group, name = "/".join(rel.parts[:-1]), rel.stem
    if group == "":
        return []
    if group == "experiment":
        return [f"+experiment={name}"]
    if group == "hydra/launcher":
        return [f"hydra/launcher={name}"]
    if group == "study":  # a MountainCar latent-space study needs V_a
        return [f"+study={name}", "runner=study", "repr/action=vae"]
    if group == "sweep":  # not a run-config group: a declared sweep, checked by composing one of its values
        sweep = load_sweep(name)
        return [f"+experiment={sweep.preset}", sweep.override(sweep.others[0])]
    if group == "filmstrip":  # one per task, named after it
        return [f"+filmstrip={name}", f"env={name}"]
    if group == "algo/exploration":  # PPO's exploration settings; none goes with the other learners
        return ["algo=none"] if name == "none" else ["algo=ppo", "runner=ppo", f"algo/exploration={name}"]
    if group == "algo" and name in DBC_RUNNER_ALGOS:
        return [f"algo={name}", "env=cheetah", *DBC_RUNNER_ALGOS[name]]
    if group in ("env", "budget", "algo", "repr/state", "repr/action"):
        extra = ["runner=ppo"] if name.startswith("ppo") else []
        extra += ["env=mountaincar"] if group == "algo" and not name.startswith("dbc") else []
        extra += ["env=cheetah", "runner=dbc"] if name.startswith("dbc") else []
        extra += ["env=carracing"] if group == "repr/state" and name == "vae" else []  # V_s needs frames
        return [f"{group}={name}", *extra]
    if group.endswith("per_env"):  # <choice>_<env> or <env>_<profile> (budget)
        first, second = name.rsplit("_", 1)
        if group == "budget/per_env":
            return [f"env={first}", f"budget={second}"]
        parent = group.removesuffix("/per_env")
        runner = [f"runner={first}"] if parent == "algo" else []
        runner += ["algo=ppo", "runner=ppo"] if parent == "algo/exploration" else []  # PPO's exploration
        return [*runner, f"{parent}={first}", f"env={second}"]
    if group == "budget/per_exploration":  # <algo>_<env>_<exploration>_<profile>
        algo, env, exploration, profile = name.split("_")
        return [f"algo={algo}", f"runner={algo}", f"algo/exploration={exploration}", f"env={env}",
                f"budget={profile}"]
    if group == "budget/per_state_repr":  # <env>_<state repr>_<profile>
        env, state, profile = name.split("_")
        return [f"repr/state={state}", f"env={env}", f"budget={profile}"]
    if group == "env/backend":  # <env>_<profile>: the simulator engine a profile uses for a task
        env, profile = name.rsplit("_", 1)
        return [f"env={env}", f"budget={profile}"]
    if group == "env/per_algo":  # <env>_<algo>: an env setting a learner's reference sets per task
        env, algo = name.split("_", 1)  # the algo choice may hold "_" (dbc_readme)
        return [f"env={env}", f"algo={algo}", *DBC_RUNNER_ALGOS.get(algo, [])]
    if group in ("algo/per_budget", "budget/per_recipe"):  # <algo>_<env>_<profile>
        algo, env, profile = name.rsplit("_", 2)  # the algo choice may hold "_" (dbc_readme)
        runner = DBC_RUNNER_ALGOS.get(algo, [f"runner={algo.split('_')[0]}"])
        return [f"algo={algo}", *runner, f"env={env}", f"budget={profile}"]
    raise AssertionError(f"no composition rule for {rel}: add one to tests/test_config.py")


ALL_YAML = sorted(CONF_DIR.rglob("*.yaml"))


@pytest.mark.parametrize("yaml_path", ALL_YAML, ids=lambda p: str(p.relative_to(CONF_DIR)))
def test_every_yaml_composes_and_validates(yaml_path: Path) -> None:
    cfg = compose(overrides_for(yaml_path))
    assert cfg.env.name in ENV_NAMES


@pytest.mark.parametrize("budget", BUDGET_NAMES)
@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_every_experiment_composes_at_every_budget(experiment: str, budget: str) -> None:
    cfg = compose([f"+experiment={experiment}", f"budget={budget}"])
    assert cfg.experiment == experiment
    assert cfg.budget.name == budget


def test_every_yaml_key_has_a_comment() -> None:
    """House rule: every value in conf/ says where it comes from."""
    bare = []
    for path in ALL_YAML:
        for number, line in enumerate(path.read_text().splitlines(), 1):
            text = line.strip()
            if not text or text.startswith("#") or text.startswith("- ") or text == "defaults:":
                continue
            if text.endswith(":") and "#" not in text:  # a section header, e.g. `ppo:` or `hydra:`
                continue
            if "#" not in text:
                bare.append(f"{path.relative_to(CONF_DIR)}:{number}: {text}")
    assert not bare, "yaml values without a source comment:\n" + "\n".join(bare)


@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_a_learners_runner_follows_from_its_algo_alone(experiment: str) -> None:
    """A preset names its learner once (``override /algo``): conf/config.yaml's ``runner:`` follows
    it. Only presets that learn no policy say what they run instead (collect, repr or study)."""
    preset = yaml.safe_load((CONF_DIR / "experiment" / f"{experiment}.yaml").read_text())
    cfg = compose([f"+experiment={experiment}"])
    if cfg.algo.name == "none":
        assert cfg.runner in ("collect", "repr", "study")
    else:
        assert "runner" not in preset, f"conf/experiment/{experiment}.yaml: drop runner, its algo implies it"
        assert cfg.runner == cfg.algo.name


def test_an_algo_alone_on_the_command_line_picks_its_runner() -> None:
    assert compose(["algo=dbc_readme", "env=cheetah"]).runner == "dbc"
    assert compose(["algo=ppo", "env=mountaincar"]).runner == "ppo"
    assert compose(["env=mountaincar"]).runner == "collect"


def test_no_budget_file_sets_an_algorithm_hyperparameter() -> None:
    """Issue 25: a budget sizes a run; an algorithm's settings at a profile live in conf/algo/per_budget/.
    Every file under conf/budget/ holds only budget keys, and every budget layer lands in ``budget``."""
    allowed = {f.name for f in fields(BudgetConfig)} | {"defaults"}
    for path in sorted((CONF_DIR / "budget").rglob("*.yaml")):
        text = path.read_text()
        keys = set(yaml.safe_load(text) or {})
        assert "@package" not in text and keys <= allowed, (
            f"conf/{path.relative_to(CONF_DIR)} sets {sorted(keys - allowed) or 'a package'}: an algorithm "
            "hyper-parameter belongs in conf/algo/ (per profile: conf/algo/per_budget/)")
    entries = yaml.safe_load((CONF_DIR / "config.yaml").read_text())["defaults"]
    layers = [e if isinstance(e, str) else next(iter(e)) for e in entries]
    budget_layers = [e for e in layers if e.removeprefix("optional ").startswith("budget")]
    assert budget_layers and all(e == "budget" or e.endswith("@budget") for e in budget_layers), budget_layers


TABLE_1 = {"n_steps": 512, "learning_rate": 4e-4, "n_epochs": 10, "batch_size": 128, "n_envs": 32,
           "gamma": 0.99, "gae_lambda": 0.95, "clip_range": 0.2, "vf_coef": 0.5, "ent_coef": 0.01}
TABLE_2 = {"n_steps": 1000, "learning_rate": 1e-4, "n_epochs": 10, "batch_size": 1000, "n_envs": 16,
           "gamma": 0.99, "gae_lambda": 0.95, "clip_range": 0.2, "vf_coef": 0.5, "ent_coef": 0.01}


@pytest.mark.parametrize(("env", "table"), [("mountaincar", TABLE_1), ("carracing", TABLE_2)])
def test_paper_budget_carries_the_papers_ppo_table(env: str, table: dict[str, float]) -> None:
    cfg = compose(["algo=ppo", "runner=ppo", f"env={env}", "budget=paper"])
    assert cfg.algo.ppo is not None
    for key, value in table.items():
        assert getattr(cfg.algo.ppo, key) == pytest.approx(value), key


def test_cli_prints_the_composed_job_config(tmp_path: Path) -> None:
    done = run_cli("--cfg", "job", "algo=ppo", "runner=ppo", "env=mountaincar", "budget=paper",
                   f"runs_dir={tmp_path}")
    assert done.returncode == 0, done.stderr
    assert "n_steps: 512" in done.stdout and "learning_rate: 0.0004" in done.stdout
    assert not any(tmp_path.iterdir()), "--cfg must not create run directories"


BAD_INPUTS = [
    (["algo=ppo", "runner=ppo", "algo.ppo.learning_rate=-1"], "algo.ppo.learning_rate"),
    (["algo=ppo", "runner=ppo", "algo.ppo.activation=elu"], "algo.ppo.activation"),  # V_a has elu, PPO nets do not
    (["repr/action=vae", "repr.action.latent_dim=0"], "repr.action.latent_dim"),
    (["repr.state.latent_dim=0"], "repr.state.latent_dim"),
    (["env=foo"], "env/foo"),
    (["env.name=foo"], "env.name"),
    (["seed=abc"], "seed"),
    (["seed=-3"], "seed"),
    (["repr.action.latnt_dim=3"], "latnt_dim"),
    (["budget.trials=0"], "budget.trials"),
    (["+study=onestep", "runner=study", "repr/action=vae", "study.s0=[0.9,0.0]"], "study.s0"),
    # frames too small for the conv stack that sees them (a shape error after the run dir, before)
    (["+experiment=cheetah_dbc", "env.image_size=7"], "env.image_size"),
    (["+experiment=carracing_ppo", "env.image_size=7"], "env.image_size"),
    (["+experiment=carracing_ppo_vs", "env.image_size=7"], "env.image_size"),
    (["+experiment=cheetah_dbc", "env.frame_stack=0"], "env.frame_stack"),
    (["+experiment=cheetah_dbc", "env.camera_id=-1"], "env.camera_id"),
    (["+experiment=cheetah_dbc", "env.visuals=night"], "env.visuals"),
    (["+experiment=mountaincar_ppo", "env.visuals=dbc_reference"], "env.visuals"),  # restyles dm_control only
    # exploration settings the paper leaves open (algo/exploration, gSDE)
    (["+experiment=mountaincar_ppo", "algo.ppo.sde_sample_freq=-1"], "algo.ppo.sde_sample_freq"),
    (["+experiment=mountaincar_ppo", "algo.ppo.sde_sample_freq=4"], "algo.ppo.sde_sample_freq"),  # without gSDE
    (["+experiment=mountaincar_ppo", "algo/exploration=levy"], "algo/exploration"),
    # env backends: an unknown engine, and envpool for a task it does not ship
    (["+experiment=carracing_ppo", "env.backend=brax"], "env.backend"),
    (["+experiment=cheetah_dbc", "env.backend=envpool"], "env.backend"),
    (["+experiment=carracing_ppo", "env.backend=envpool", "env.backend_threads=-1"], "env.backend_threads"),
    # the conv trunks' precision: fp32 | bf16 (fp16 has no CPU autocast and no scaler here)
    (["+experiment=carracing_ppo", "precision=fp16"], "precision"),
]


@pytest.mark.parametrize(("overrides", "key"), BAD_INPUTS,
                         ids=[" ".join([*(o[12:] for o in overrides if o.startswith("+experiment=")), key])
                              for overrides, key in BAD_INPUTS])
def test_bad_input_is_refused_before_any_run_dir(overrides: list[str], key: str, tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    preset = [] if any(o.startswith("+experiment=") for o in overrides) else ["+experiment=mountaincar_data"]
    done = run_cli(*preset, f"runs_dir={runs}", *overrides)
    assert done.returncode == 2, done.stdout + done.stderr
    message = done.stderr.strip().splitlines()
    assert len(message) == 1 and key in message[0], done.stderr
    assert not runs.exists(), "an invalid config must not create a run directory"


def test_bad_value_in_one_job_of_a_multirun_is_refused(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    done = run_cli("-m", "+experiment=mountaincar_data", f"runs_dir={runs}", "seed=0,-1")
    assert done.returncode == 2 and "seed" in done.stderr
    assert not runs.exists()


@pytest.mark.parametrize("kind", UNWRITABLE)
def test_a_runs_dir_that_cannot_be_written_is_refused_in_one_line(kind: str, tmp_path: Path) -> None:
    runs = unwritable_path(kind, tmp_path)
    for multirun in ([], ["-m"]):
        done = run_cli(*multirun, "+experiment=mountaincar_data", f"runs_dir={runs}")
        assert done.returncode == 2, done.stdout + done.stderr
        assert done.stderr.strip().splitlines() == [f"plls_bench: invalid config: runs_dir: cannot create or write "
                                                    f"{runs}: {runs.parent} {unwritable_reason(kind, runs)}"]
    assert not runs.exists()


def test_compose_raises_config_error_naming_the_key() -> None:
    with pytest.raises(ConfigError, match="budget.eval_episodes"):
        compose(["budget.eval_episodes=-1"])
