"""MountainCar latent-space studies (Figs 7-9): sampling, the car, the measures, the runner."""
from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from plls_bench.config import ConfigError
from plls_bench.core.atomic_files import read_json
from plls_bench.pipeline.execute import execute
from plls_bench.report import render_all
from plls_bench.report.collect import verify_outputs
from plls_bench.repr.store import ensure_representations
from plls_bench.repr.train import new_model
from plls_bench.rundirs.composition import compose
from plls_bench.studies import measures
from plls_bench.studies.latent_space import (
    STUDIES,
    encode,
    reconstruction,
    sample_actions,
    structure,
    study_rngs,
    tracking_steps,
)
from plls_bench.studies.mountaincar import MountainCar
from tests.conftest import compose_preset, run_cli
from tests.synthetic_runs import finish, make_run

PRESETS = {"multistep": "mountaincar_multistep", "onestep": "mountaincar_onestep",
           "generalisation": "mountaincar_generalisation"}
# The "What each runner writes" arrays (docs/architecture.md) at the paper's sizes (D = V_a's latent size).
D = 3
CONTRACT = {
    "multistep": {"actions": (1000,), "mu": (1000, D), "e": (1000, D), "decoded": (1000,),
                  "states_raw": (1001, 2), "states_decoded": (1001, 2)},
    "onestep": {"actions": (1000,), "mu": (1000, D), "e": (1000, D), "decoded": (1000,),
                "next_states_raw": (1000, 2), "next_states_decoded": (1000, 2), "s0": (2,)},
    "generalisation": {"actions": (10,), "mu": (10, D), "std": (10, D), "e": (10, 10, D), "decoded": (10, 10),
                       "next_states": (10, 10, 2), "next_states_raw": (10, 2), "s0": (2,)},
}


# --------------------------------------------------------------------------- sampling
def test_onestep_actions_are_500_left_then_500_right(tmp_path: Path) -> None:
    study = compose_preset("mountaincar_onestep", tmp_path).study
    actions = sample_actions(study, np.random.default_rng(0))
    assert actions.shape == (1000,)
    assert ((actions[:500] >= -1) & (actions[:500] < 0)).all()
    assert ((actions[500:] > 0) & (actions[500:] <= 1)).all()
    assert np.array_equal(actions, sample_actions(study, np.random.default_rng(0)))


def test_half_open_ranges_exclude_zero_even_at_the_generators_extremes() -> None:
    class Extremes:  # a generator that returns exactly 0.0, the end numpy's random() includes
        def random(self, n: int) -> np.ndarray:
            return np.zeros(n)

    study = compose(["+study=onestep", "runner=study", "repr/action=vae"]).study
    actions = sample_actions(study, Extremes())  # type: ignore[arg-type]
    assert set(actions[:500]) == {-1.0} and set(actions[500:]) == {1.0}


def test_study_streams_are_seeded_per_trial_and_independent(tmp_path: Path) -> None:
    draws = [[rng.random(4) for rng in study_rngs(compose_preset("mountaincar_onestep", tmp_path, f"seed={k}"))]
             for k in (0, 0, 1)]
    assert all(np.array_equal(a, b) for a, b in zip(draws[0], draws[1]))
    assert not any(np.array_equal(a, b) for a, b in zip(draws[0], draws[2]))
    assert not np.array_equal(draws[0][0], draws[0][1])


# --------------------------------------------------------------------------- the car
def gym_physics(x: float, v: float, a: float) -> tuple[float, float]:
    """MountainCarContinuous-v0's update, written out (no boundary hit in these tests)."""
    v = v + max(-1.0, min(1.0, a)) * 0.0015 - 0.0025 * math.cos(3 * x)
    return x + v, v


def test_car_starts_where_told_and_runs_past_the_time_limit(tmp_path: Path) -> None:
    env_cfg = compose_preset("mountaincar_multistep", tmp_path).env
    rng = np.random.default_rng(1)
    actions = rng.uniform(-1, 1, 1200)  # longer than max_episode_steps = 999
    with MountainCar(env_cfg) as car:
        states = car.trajectory(np.array([-0.5, 0.01]), actions)
        next_states = car.one_step(np.array([-0.5233, 0.0]), np.array([[-1.0, 0.0, 0.5]]))
    assert states.shape == (1201, 2) and np.array_equal(states[0], [-0.5, 0.01])
    x, v = gym_physics(-0.5, 0.01, actions[0])
    assert states[1] == pytest.approx([x, v], abs=1e-6)
    assert next_states.shape == (1, 3, 2)
    for got, a in zip(next_states[0], (-1.0, 0.0, 0.5)):
        assert got == pytest.approx(gym_physics(-0.5233, 0.0, a), abs=1e-7)


# --------------------------------------------------------------------------- the measures
def test_measures_score_structure_high_and_noise_at_chance() -> None:
    rng = np.random.default_rng(0)
    a = rng.uniform(-1, 1, 400)
    smooth = np.stack([np.tanh(2 * a), a ** 3, 0.5 * a], axis=1)  # a monotone curve in 3-D
    noise = rng.standard_normal((400, 3))
    assert measures.distance_rank_correlation(a, smooth) > 0.95
    assert abs(measures.distance_rank_correlation(a, noise)) < 0.1
    assert measures.knn_overlap(a, smooth, 10) > 0.95
    assert measures.knn_overlap(a, noise, 10) < 0.1
    assert measures.linear_separability(smooth, a < 0) == 1.0
    assert measures.linear_separability(smooth[:, :1] + 0.01, a < 0) == 1.0  # threshold away from 0
    assert 0.45 < measures.linear_separability(noise, a < 0) < 0.65


def test_deviation_and_state_error_on_known_values() -> None:
    stats = measures.deviation_stats(np.array([0.5, -0.5]), np.array([[0.6, 0.4], [-0.5, 0.1]]))
    assert stats["mean_abs_action_error"] == pytest.approx((0.1 + 0.1 + 0.0 + 0.6) / 4)
    assert stats["mean_action_deviation"] == pytest.approx((0.1 - 0.1 + 0.0 + 0.6) / 4)
    assert stats["max_abs_action_error"] == pytest.approx(0.6)
    assert stats["sign_agreement"] == pytest.approx(3 / 4)
    error = measures.state_error(np.array([[0.3, 0.0], [0.0, 0.0]]), np.zeros((2, 2)), np.array([1.5, 0.14]))
    assert error == pytest.approx(0.1)
    raw, scale = np.zeros((11, 2)), np.array([1.8, 0.14])
    apart = raw.copy()
    apart[5:, 1] = 0.14 * 0.06  # 6% of the velocity span from step 5 on
    assert tracking_steps(raw, raw, scale, 0.05) == 10 and tracking_steps(raw, apart, scale, 0.05) == 5


# --------------------------------------------------------------------------- trained vs untrained V_a
def run_study(name: str, vae, cfg) -> dict[str, float]:
    study = cfg.study
    actions_rng, eps_rng, shuffle_rng = study_rngs(cfg)
    with MountainCar(cfg.env) as car:
        enc = encode(vae, sample_actions(study, actions_rng), study.samples_per_action, eps_rng, study.decode,
                     (car.action_low, car.action_high))
        _, dynamics = STUDIES[name](enc, car, study, shuffle_rng.permutation(len(enc.actions)))
    return {**structure(enc, study.knn), **reconstruction(enc), **dynamics}


def test_the_numbers_tell_a_trained_va_from_an_untrained_one(tmp_path: Path) -> None:
    """The claims' numbers must be able to fail: an untrained V_a (random weights) decodes to
    actions unrelated to the raw ones, so its reconstructions drive the car no better than
    shuffled actions, and left/right are not told apart by decoding."""
    cfg = compose_preset("mountaincar_onestep", tmp_path)
    trained = run_study("onestep", ensure_representations(cfg).action_vae, cfg)
    untrained = run_study("onestep", new_model(cfg, "action", 1).eval(), cfg)
    assert trained["recon/mean_abs_action_error"] < 0.25 < untrained["recon/mean_abs_action_error"]
    assert trained["dynamics/state_error_vs_shuffled"] < 0.5 < untrained["dynamics/state_error_vs_shuffled"]
    assert trained["recon/sign_agreement"] > 0.85 > untrained["recon/sign_agreement"]
    assert trained["structure/spearman_action_mu_distance"] > 0.9
    assert trained["structure/left_right_separability_mu"] > 0.9


# --------------------------------------------------------------------------- the runner, end to end
@pytest.fixture(scope="module")
def study_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The three presets at smoke budget in one runs dir (one shared V_a)."""
    runs_dir = tmp_path_factory.mktemp("studies") / "runs"
    out = {}
    for name, preset in PRESETS.items():
        cfg = compose_preset(preset, runs_dir)
        out[name] = runs_dir / preset / "default" / "seed=0"
        assert execute(cfg, out[name]) == "done"
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", list(PRESETS))
def test_study_preset_writes_the_readme_arrays_and_numbers(name: str, study_runs: dict[str, Path]) -> None:
    run_dir = study_runs[name]
    with np.load(run_dir / "studies" / f"{name}.npz", allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    assert {k: a.shape for k, a in arrays.items()} == CONTRACT[name]
    assert all(np.isfinite(a).all() for a in arrays.values())
    assert (np.abs(arrays["decoded"]) <= 1).all()
    if "s0" in arrays:
        assert arrays["s0"].tolist() == [-0.5233, 0.0]
    else:
        assert arrays["states_raw"][0].tolist() == arrays["states_decoded"][0].tolist() == [-1.2, 0.0]
    metrics = read_json(run_dir / "metrics" / "study.json")
    numbers = {k: v for k, v in metrics.items() if k.split("/")[0] in ("structure", "recon", "dynamics")}
    assert {"structure/spearman_action_latent_distance", "structure/left_right_separability",
            "recon/mean_abs_action_error", "dynamics/mean_state_error"} <= set(numbers)
    assert all(np.isfinite(v) for v in numbers.values())
    assert metrics["va_latent_dim"] == D and len(metrics["va_artifact"]) == 16
    assert read_json(run_dir / "status.json")["state"] == "done"


@pytest.mark.slow
def test_a_study_is_reproducible_byte_for_byte(study_runs: dict[str, Path]) -> None:
    runs_dir = study_runs["onestep"].parents[2]
    again = runs_dir / "again" / "seed=0"
    assert execute(compose_preset("mountaincar_onestep", runs_dir), again) == "done"
    for rel in ("studies/onestep.npz", "metrics/study.json"):
        assert (again / rel).read_bytes() == (study_runs["onestep"] / rel).read_bytes()


def render_ok(runs_dir: Path, out: Path, ids: list[str]) -> None:
    """The collector draws ``ids`` from ``runs_dir`` without a gap, and the images are not blank."""
    statuses = render_all(runs_dir, out, only=ids)
    assert {i: (s.status, s.gaps) for i, s in statuses.items()} == {i: ("ok", []) for i in ids}
    assert verify_outputs(out, statuses) == []


@pytest.mark.slow
def test_the_collector_draws_figs_7_to_9_from_the_study_runs(study_runs: dict[str, Path], tmp_path: Path) -> None:
    runs_dir = study_runs["onestep"].parents[2]
    render_ok(runs_dir, tmp_path / "out", ["fig07", "fig08", "fig09"])
    fig08 = pd.read_csv(tmp_path / "out" / "figures" / "fig08.csv")
    with np.load(study_runs["onestep"] / "studies" / "onestep.npz") as npz:
        assert np.allclose(fig08[["e_l", "e_m", "e_n"]].to_numpy(), npz["e"])  # D = 3: e itself


@pytest.mark.slow
def test_cli_reruns_a_study_against_another_va(tmp_path: Path) -> None:
    done = run_cli("+experiment=mountaincar_generalisation", "repr.action.latent_dim=8",
                   f"runs_dir={tmp_path / 'runs'}", "progress=false")
    assert done.returncode == 0, done.stderr[-2000:]
    run_dir = tmp_path / "runs" / "mountaincar_generalisation" / "repr.action.latent_dim=8" / "seed=0"
    with np.load(run_dir / "studies" / "generalisation.npz") as npz:
        assert npz["mu"].shape == (10, 8) and npz["e"].shape == (10, 10, 8)
    assert read_json(run_dir / "metrics" / "study.json")["va_latent_dim"] == 8
    # The collector reads variant `default`: put this run there to check it draws N_e = 8 (PCA).
    shutil.copytree(run_dir, run_dir.parents[1] / "default" / "seed=0")
    render_ok(tmp_path / "runs", tmp_path / "out", ["fig09"])


BAD_STUDIES = [
    (["study.s0=[0.9,0.0]"], "study.s0"),
    (["study.s0=[-0.5]"], "study.s0"),
    (["study.action_ranges=[[0.5,-0.5]]"], "study.action_ranges[0]"),
    (["study.decode=sigma"], "study.decode"),
    (["study.samples_per_action=3"], "study.samples_per_action"),
    (["repr/action=none"], "repr.action.kind"),
    (["env=carracing"], "env"),
]


@pytest.mark.parametrize(("overrides", "key"), BAD_STUDIES, ids=[k for _, k in BAD_STUDIES])
def test_bad_study_settings_name_the_key(overrides: list[str], key: str, tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as err:
        compose_preset("mountaincar_onestep", tmp_path, *overrides)
    assert str(err.value).startswith(f"{key}:") or f"{key}:" in str(err.value), err.value


def test_paper_vs_suite_judges_the_study_claims_over_trials(tmp_path: Path) -> None:
    """claims.csv's `study` rows read metrics/study.json of every trial: mean and Student t interval."""
    # three trials, the fewest a threshold row is read from: 0.96 ± t(0.975, 2) x 0.01 / sqrt(3), where the
    # percentile bootstrap was exactly [min, max] (each extreme is a whole resample with probability 1/27 > 2.5%)
    for seed, (rho, ratio) in enumerate([(0.95, 0.1), (0.97, 0.5), (0.96, 0.3)]):
        run, cfg = make_run(tmp_path / "runs", "mountaincar_multistep", seed, "quick")
        run.write_json("metrics/study.json", {"structure/spearman_action_mu_distance": rho,
                                              "dynamics/state_error_vs_shuffled": ratio})
        finish(run, cfg)
    render_all(tmp_path / "runs", tmp_path / "out", only=["claims"])
    claims = pd.read_csv(tmp_path / "out" / "tables" / "claims.csv").set_index("claim")
    near = claims.loc["Neighbouring actions have neighbouring action representations (mu)"]
    half = 4.302653 * 0.01 / 3 ** 0.5
    assert (near["suite_value"], near["ci_low"], near["ci_high"]) == pytest.approx((0.96, 0.96 - half, 0.96 + half))
    assert near["verdict"] == "reproduced" and near["budget"] == "quick (3 trials)"
    raw_vs_decoded = "Reconstructed actions move the car like the raw ones over 1000 steps"
    assert claims.loc[raw_vs_decoded, "verdict"] == "inconclusive"
    sampled = claims.loc["Neighbouring actions have neighbouring action representations (sampled e, as plotted)"]
    assert sampled["verdict"] == "not run at this budget" and "no structure/spearman_action_latent" in sampled["reason"]
