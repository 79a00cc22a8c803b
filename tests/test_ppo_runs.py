"""PPO presets end to end at smoke budget: the run-dir contract, overrides, resume after SIGKILL or SIGTERM."""
from __future__ import annotations

import csv
import json
import signal
import subprocess
import time
from pathlib import Path

import pytest

from plls_bench.core.atomic_files import read_jsonl
from plls_bench.pipeline.execute import execute
from plls_bench.rundirs.run_dir import ARCHITECTURE_FILE, PARAMS_FILE, Run
from plls_bench.train.ppo_model import build_vec_env, load_trained
from plls_bench.train.schedule import Schedule
from tests.conftest import compose_preset, run_cli, start_cli

PPO_PRESETS = ["mountaincar_ppo", "mountaincar_plls_ppo", "mountaincar_ppo_gsde", "mountaincar_plls_ppo_gsde",
               "mountaincar_ppo_zoo", "carracing_ppo", "carracing_plls_ppo", "carracing_ppo_vs", "carracing_ppo_va"]
EVAL_KEYS = {"env_steps", "iteration", "agent_steps", "wall_s", "episode_returns", "return_mean",
             "episode_lengths", "episode_returns_stochastic", "return_mean_stochastic"}
TRAIN_KEYS = {"env_steps", "iteration", "agent_steps", "wall_s", "loss/policy", "loss/value",
              "loss/entropy", "train/approx_kl", "train/clip_fraction", "perf/sps"}


def check_run_contract(run_dir: Path, plan: Schedule, eval_episodes: int) -> None:
    """What the collector reads from a finished PPO run."""
    run = Run(run_dir)
    assert (run.read_status() or {}).get("state") == "done"
    evals, trains = run.read_metrics("eval"), run.read_metrics("train")
    expected = [i for i in range(plan.iterations + 1) if plan.eval_at(i)]
    assert [r["iteration"] for r in evals] == expected, "one eval row per scheduled iteration, no duplicates"
    assert [r["iteration"] for r in trains] == list(range(1, plan.iterations + 1))
    for row in evals:
        assert EVAL_KEYS <= set(row), EVAL_KEYS - set(row)
        assert len(row["episode_returns"]) == len(row["episode_returns_stochastic"]) == eval_episodes
        assert row["env_steps"] == row["iteration"] * plan.env_steps_per_iteration
    for row in trains:
        assert TRAIN_KEYS <= set(row), TRAIN_KEYS - set(row)
    wall = [r["wall_s"] for r in evals]
    assert wall == sorted(wall)
    params = json.loads((run_dir / PARAMS_FILE).read_text())
    assert params["modules"]["policy"]["trainable"] == params["trainable"] > 0
    assert (run_dir / ARCHITECTURE_FILE).is_file()
    csv_rows = [row for path in sorted(run_dir.glob("sb3/*/progress.csv")) for row in csv.DictReader(open(path))]
    assert {int(float(r["time/iteration"])) for r in csv_rows} == set(range(1, plan.iterations + 1))
    assert list(run_dir.glob("sb3/*/events.out.tfevents.*")), "TensorBoard output"


@pytest.fixture(scope="module")
def shared_runs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One runs_dir for the presets of this module: random-policy data and V_s / V_a artifacts
    are built once and reused, as the trials of a task share them."""
    return tmp_path_factory.mktemp("ppo") / "runs"


@pytest.mark.slow
@pytest.mark.parametrize("preset", PPO_PRESETS)
def test_preset_runs_end_to_end_at_smoke_budget(preset: str, shared_runs: Path) -> None:
    cfg = compose_preset(preset, shared_runs)
    run_dir = shared_runs / preset / "default" / "seed=0"
    assert execute(cfg, run_dir) == "done"
    check_run_contract(run_dir, Schedule.of(cfg), cfg.budget.eval_episodes)
    params = json.loads((run_dir / PARAMS_FILE).read_text())
    frozen = {"V_s.encoder"} if cfg.repr.state.kind == "vae" else set()
    frozen |= {"V_a.decoder"} if cfg.repr.action.kind == "vae" else set()
    assert set(params["modules"]) == {"policy", *frozen}, "total counts every module run, frozen ones too"
    assert params["total"] == sum(m["total"] for m in params["modules"].values())
    assert (params["total"] > params["trainable"]) == bool(frozen)
    trained = load_trained(run_dir)
    assert trained.cfg == cfg
    venv = build_vec_env(cfg, 1, seed=0, reprs=trained.reprs)
    actions = trained.act(venv.reset())
    venv.close()
    assert actions.shape == (1, *trained.model.action_space.shape)


@pytest.mark.slow
def test_evaluation_never_shifts_training(runs_dir: Path) -> None:
    """Evaluating more often or with more episodes leaves every training number unchanged: eval
    envs are separate and stochastic test actions sample from their own stream."""
    losses = []
    for name, overrides in (("a", []), ("b", ["budget.eval_every_env_steps=1024", "budget.eval_episodes=3"])):
        cfg = compose_preset("mountaincar_ppo", runs_dir, *overrides)
        execute(cfg, runs_dir / name)
        losses.append([(r["loss/policy"], r["loss/value"]) for r in Run(runs_dir / name).read_metrics("train")])
    assert losses[0] == losses[1]


@pytest.mark.slow
def test_hyper_parameters_are_overridable_from_the_command_line(shared_runs: Path) -> None:
    done = run_cli("+experiment=mountaincar_plls_ppo", f"runs_dir={shared_runs}", "progress=false",
                   "algo.ppo.learning_rate=1e-3", "repr.action.latent_dim=8", "algo.ppo.n_epochs=2",
                   "algo.ppo.policy_hidden=[16]")
    assert done.returncode == 0, done.stdout + done.stderr
    run_dirs = [p for p in shared_runs.glob("mountaincar_plls_ppo/*/seed=0") if p.parent.name != "default"]
    assert len(run_dirs) == 1 and "learning_rate=1e-3" in run_dirs[0].parent.name
    trains = Run(run_dirs[0]).read_metrics("train")
    assert trains[0]["train/learning_rate"] == pytest.approx(1e-3)
    assert [r["train/n_updates"] for r in trains] == [2, 4], "n_epochs=2 per iteration reached SB3"
    params = json.loads((run_dirs[0] / PARAMS_FILE).read_text())
    e = 8  # the policy now emits e in R^8 through a V_a trained with latent_dim=8
    assert params["modules"]["policy"]["trainable"] == (2 * 16 + 16) + (16 * e + e) + e + (16 + 1)


def start_and_wait_for_train_rows(args: list[str], run_dir: Path, rows: int) -> subprocess.Popen[str]:
    """The CLI started in the background, once its run has logged ``rows`` training iterations."""
    proc = start_cli(*args)
    deadline = time.monotonic() + 300
    while len(read_jsonl(run_dir / "metrics" / "train.jsonl")) < rows:
        assert proc.poll() is None, f"run ended too early:\n{proc.stdout.read() if proc.stdout else ''}"
        assert time.monotonic() < deadline, "run made no progress"
        time.sleep(0.05)
    return proc


@pytest.mark.slow
@pytest.mark.parametrize("sig, exit_code, state", [
    (signal.SIGKILL, -signal.SIGKILL, "running"),  # no handler runs: the status stays as it was
    (signal.SIGTERM, 143, "stopped"),              # the runner records why, then exits as a shell would report
])
def test_a_signal_mid_training_then_a_relaunch_loses_and_duplicates_no_evals(
        runs_dir: Path, sig: signal.Signals, exit_code: int, state: str) -> None:
    args = ["+experiment=mountaincar_ppo", f"runs_dir={runs_dir}", "progress=false", f"variant={sig.name}",
            "budget.train_env_steps=5120", "budget.eval_every_env_steps=512"]  # 10 iterations, 11 evals
    run_dir = runs_dir / "mountaincar_ppo" / sig.name / "seed=0"
    proc = start_and_wait_for_train_rows(args, run_dir, 4)
    proc.send_signal(sig)
    output = proc.communicate(timeout=120)[0]
    status = Run(run_dir).read_status() or {}
    assert proc.returncode == exit_code, output
    assert status.get("state") == state, status
    assert state == "running" or sig.name in status.get("reason", ""), status
    assert len(read_jsonl(run_dir / "metrics" / "train.jsonl")) < 10, "stopped mid-training"

    done = run_cli(*args)
    assert done.returncode == 0, done.stdout + done.stderr
    cfg = compose_preset("mountaincar_ppo", runs_dir, "budget.train_env_steps=5120", "budget.eval_every_env_steps=512")
    check_run_contract(run_dir, Schedule.of(cfg), cfg.budget.eval_episodes)
    provenance = json.loads((run_dir / "provenance.json").read_text())
    assert len(provenance["starts"]) == 2, "the second launch resumed the same run dir"
