"""Training V_a / V_s as shared artifacts: the runner's files, learning, resume, bad checkpoints."""
from __future__ import annotations

import io
import logging
from pathlib import Path

import numpy as np
import pytest
import torch

from plls_bench.core.atomic_files import atomic_write_json, read_json, read_jsonl
from plls_bench.data import get_dataset
from plls_bench.pipeline.execute import execute
from plls_bench.repr.keys import sha256
from plls_bench.repr.store import (
    CheckpointError,
    CheckpointMismatch,
    ensure_artifact,
    ensure_representations,
    load_weights,
)
from plls_bench.repr.train import new_model
from plls_bench.rundirs.run_dir import ARCHITECTURE_FILE, PARAMS_FILE
from tests.conftest import compose_preset, in_two_processes, run_cli

EPOCH_KEYS = {"model", "epoch", "train_loss", "train_recon_mse", "train_kl", "val_loss", "val_recon_mse", "val_kl"}


def ensure_va(cfg) -> torch.nn.Module:
    """The config's V_a through the runners' one representation step (built on first use)."""
    vae = ensure_representations(cfg).action_vae
    assert vae is not None
    return vae


def run_preset(preset: str, runs_dir: Path, *overrides: str) -> Path:
    cfg = compose_preset(preset, runs_dir, *overrides)
    run_dir = runs_dir / preset / "default" / f"seed={cfg.seed}"
    assert execute(cfg, run_dir) == "done"
    return run_dir


def check_repr_run(run_dir: Path, models: dict[str, int]) -> dict:
    """The README's repr files: ``models`` maps each trained model to its epoch count."""
    rows = read_jsonl(run_dir / "metrics" / "repr_train.jsonl")
    for model, epochs in models.items():
        mine = [r for r in rows if r["model"] == model]
        assert [r["epoch"] for r in mine] == list(range(1, epochs + 1))
        assert all(EPOCH_KEYS <= set(r) and np.isfinite(r["val_loss"]) for r in mine)
    test = read_json(run_dir / "metrics" / "repr_test.json")
    assert set(test) == set(models)
    assert all({"test_mse", "n_test", "artifact"} <= set(t) and t["n_test"] > 0 for t in test.values())
    params = read_json(run_dir / PARAMS_FILE)
    assert params["total"] == sum(m["total"] for m in params["modules"].values()) > 0
    architecture = read_json(run_dir / ARCHITECTURE_FILE)
    assert set(architecture) == set(params["modules"])
    return test


@pytest.mark.slow
def test_mountaincar_va_preset_from_the_command_line(runs_dir: Path) -> None:
    done = run_cli("+experiment=mountaincar_va", f"runs_dir={runs_dir}", "progress=false")
    assert done.returncode == 0, done.stderr[-2000:]
    run_dir = runs_dir / "mountaincar_va" / "default" / "seed=0"
    assert read_json(run_dir / "status.json")["state"] == "done"
    cfg = compose_preset("mountaincar_va", runs_dir)
    test = check_repr_run(run_dir, {"action": cfg.budget.epochs_for("action")})
    samples = np.load(run_dir / "samples" / "action_reconstructions.npz")
    first = min(200, test["action"]["n_test"])  # Fig. 16: the first 200 test actions
    assert samples["actions"].shape == samples["reconstructions"].shape == (first, 1)
    data, _ = get_dataset(cfg)
    assert np.array_equal(samples["actions"], data.action_split("test")[:first])


@pytest.mark.slow
def test_carracing_presets_train_vs_and_va_on_one_dataset(runs_dir: Path) -> None:
    vs_dir, va_dir = run_preset("carracing_vs", runs_dir), run_preset("carracing_va", runs_dir)
    budget = compose_preset("carracing_vs", runs_dir).budget
    check_repr_run(vs_dir, {"state": budget.epochs_for("state")})
    check_repr_run(va_dir, {"action": budget.epochs_for("action")})
    assert len(list((runs_dir / "artifacts" / "data").iterdir())) == 2  # one dataset + its lock
    frames = np.load(vs_dir / "samples" / "state_reconstructions.npz")
    assert frames["originals"].dtype == frames["reconstructions"].dtype == np.uint8
    assert frames["originals"].shape == frames["reconstructions"].shape == (len(frames["labels"]), 3, 96, 96)
    assert set(frames["labels"]) <= {"road", "grass"} and "road" in set(frames["labels"])
    arch = read_json(vs_dir / ARCHITECTURE_FILE)
    assert arch["V_s.decoder"][-1]["output_shape"] == [1, 3, 96, 96]


@pytest.mark.slow
def test_cheetah_va_preset(runs_dir: Path) -> None:
    run_dir = run_preset("cheetah_va", runs_dir)
    check_repr_run(run_dir, {"action": compose_preset("cheetah_va", runs_dir).budget.epochs_for("action")})
    assert np.load(run_dir / "samples" / "action_reconstructions.npz")["actions"].shape[1] == 6


def test_a_second_trial_reuses_the_artifact_and_still_gets_every_metric(runs_dir: Path) -> None:
    shared = "repr.per_trial_training=false"  # the default outside the V_a presets (PL-LS runs)
    first = run_preset("mountaincar_va", runs_dir, shared)
    second = run_preset("mountaincar_va", runs_dir, shared, "seed=1")
    tests = [read_json(d / "metrics" / "repr_test.json")["action"] for d in (first, second)]
    assert tests[0].pop("built_by_this_run") and not tests[1].pop("built_by_this_run")
    assert tests[0] == tests[1]
    for name in ("metrics/repr_train.jsonl", "samples/action_reconstructions.npz"):
        assert (first / name).read_bytes() == (second / name).read_bytes()


def test_va_preset_trains_one_model_per_trial_on_the_shared_data(runs_dir: Path) -> None:
    """The paper's V_a test MSE +- is over repeated trainings on one dataset; trial 0's model is
    the one every PL-LS run uses."""
    from plls_bench.data import dataset_key
    from plls_bench.repr.keys import repr_key

    trials = [compose_preset("mountaincar_va", runs_dir, f"seed={k}") for k in range(3)]
    assert len({str(dataset_key(c)) for c in trials}) == 1
    assert len({str(repr_key(c, "action")) for c in trials}) == 3
    plls = compose_preset("mountaincar_plls_ppo", runs_dir, "seed=4")
    assert repr_key(plls, "action") == repr_key(trials[0], "action")


def test_smoke_va_reconstructs_held_out_actions_better_than_their_mean(runs_dir: Path) -> None:
    """A collapsed or untrained V_a reconstructs every action as about the mean: it fails here."""
    cfg = compose_preset("mountaincar_va", runs_dir)
    vae = ensure_va(cfg)
    data, _ = get_dataset(cfg)
    train, test = torch.as_tensor(data.action_split("train")), torch.as_tensor(data.action_split("test"))
    baseline = float((test - train.mean(0)).pow(2).mean())
    with torch.no_grad():
        mse = float((vae.decode(vae.encode(test)[0]) - test).pow(2).mean())
    assert mse < 0.5 * baseline, (mse, baseline)
    stored = read_json(ensure_artifact(cfg, "action").path / "test.json")
    assert stored["test_mse"] < 0.5 * stored["mean_predictor_mse"]
    assert stored["mean_predictor_mse"] == pytest.approx(baseline, rel=1e-4)


def _ensure_in_child(runs_dir: str, queue) -> None:
    artifact = ensure_artifact(compose_preset("mountaincar_va", Path(runs_dir)), "action")
    queue.put((artifact.built, str(artifact.path)))


@pytest.mark.slow
def test_parallel_trials_train_the_representation_once(runs_dir: Path) -> None:
    results = in_two_processes(_ensure_in_child, str(runs_dir))
    assert sorted(built for built, _ in results) == [False, True] and results[0][1] == results[1][1]


def test_models_come_back_frozen_in_eval_mode(runs_dir: Path) -> None:
    vae = ensure_va(compose_preset("mountaincar_va", runs_dir))
    assert not vae.training and not any(p.requires_grad for p in vae.parameters())
    no_vs = compose_preset("mountaincar_va", runs_dir)
    assert ensure_representations(no_vs).state_vae is None
    with pytest.raises(ValueError, match="repr.state.kind"):
        ensure_artifact(no_vs, "state")


def state_of(model: torch.nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.clone() for k, v in model.state_dict().items()}


def test_a_killed_training_resumes_to_the_same_weights(runs_dir: Path, monkeypatch) -> None:
    reference = state_of(ensure_va(compose_preset("mountaincar_va", runs_dir / "a")))
    cfg = compose_preset("mountaincar_va", runs_dir / "b")
    import plls_bench.repr.fit as fit

    saves, real_write = [], fit.atomic_write_bytes

    def killed_after_ten_epochs(path: Path, data: bytes) -> None:
        saves.append(path)
        if len(saves) > 10:
            raise KeyboardInterrupt  # the process dies during epoch 11's checkpoint
        real_write(path, data)

    monkeypatch.setattr(fit, "atomic_write_bytes", killed_after_ten_epochs)
    with pytest.raises(KeyboardInterrupt):
        ensure_va(cfg)
    monkeypatch.setattr(fit, "atomic_write_bytes", real_write)
    partial = list((runs_dir / "b" / "artifacts" / "repr_action").glob(".*.partial"))
    assert len(partial) == 1 and torch.load(partial[0] / "resume.pt", weights_only=True)["epoch"] == 10
    resumed = ensure_va(cfg)
    assert all(torch.equal(resumed.state_dict()[k], v) for k, v in reference.items())
    history = read_json(ensure_artifact(cfg, "action").path / "history.json")
    assert [row["epoch"] for row in history] == list(range(1, cfg.budget.epochs_for("action") + 1))
    assert not list((runs_dir / "b" / "artifacts" / "repr_action").glob(".*")), "no partial or tmp left"


def test_an_incomplete_resume_file_restarts_training_from_scratch(runs_dir: Path, caplog) -> None:
    reference = state_of(ensure_va(compose_preset("mountaincar_va", runs_dir / "a")))
    cfg = compose_preset("mountaincar_va", runs_dir / "b")
    from plls_bench.repr.keys import repr_key
    from plls_bench.rundirs.artifacts import artifact_path

    final = artifact_path(cfg.runs_dir, "repr_action", repr_key(cfg, "action"))
    torn = final.parent / f".{final.name}.partial" / "resume.pt"
    torn.parent.mkdir(parents=True)
    # loadable weights but no optimizer state: the weights must not survive into the fresh start
    torch.save({"model": {k: v + 1.0 for k, v in reference.items()}, "epoch": 5}, torn)
    with caplog.at_level(logging.WARNING):
        rebuilt = ensure_va(cfg)
    assert "ignoring unreadable resume state" in caplog.text
    assert all(torch.equal(rebuilt.state_dict()[k], v) for k, v in reference.items())


def test_a_checkpoint_of_other_shapes_is_refused_naming_the_tensor(runs_dir: Path) -> None:
    cfg = compose_preset("mountaincar_va", runs_dir)
    path = ensure_artifact(cfg, "action").path / "model.pt"
    wider = new_model(compose_preset("mountaincar_va", runs_dir, "repr.action.latent_dim=8"), "action", 1)
    before = state_of(wider)
    mismatch = r"encoder\.mu\.weight: checkpoint \[3, 8\], repr.action gives \[8, 8\]"
    with pytest.raises(CheckpointMismatch, match=mismatch):
        load_weights(path, wider, "repr.action")
    assert all(torch.equal(wider.state_dict()[k], v) for k, v in before.items()), "nothing half-loaded"
    # a stored artifact whose checkpoint disagrees with the code's architecture (checksum intact)
    buffer = io.BytesIO()
    torch.save(wider.state_dict(), buffer)
    path.write_bytes(buffer.getvalue())
    meta = read_json(path.parent / "meta.json")
    atomic_write_json(path.parent / "meta.json", {**meta, "sha256": {**meta["sha256"], "model.pt": sha256(path)}})
    with pytest.raises(CheckpointMismatch, match=r"decoder\.0\.0\.weight: checkpoint \[8, 8\]"):
        ensure_va(cfg)


@pytest.mark.parametrize("damage", ["truncate", "flip", "delete_meta"])
def test_a_corrupt_artifact_is_discarded_and_rebuilt(runs_dir: Path, damage: str, caplog) -> None:
    cfg = compose_preset("mountaincar_va", runs_dir)
    reference = state_of(ensure_va(cfg))
    path = ensure_artifact(cfg, "action").path
    model_file = path / "model.pt"
    if damage == "truncate":
        model_file.write_bytes(model_file.read_bytes()[:100])
    elif damage == "flip":
        data = bytearray(model_file.read_bytes())
        data[len(data) // 2] ^= 0xFF  # a loadable file with one wrong weight
        model_file.write_bytes(bytes(data))
    else:
        (path / "meta.json").unlink()
    with caplog.at_level(logging.WARNING):
        rebuilt = ensure_va(cfg)
    assert "discarding corrupt repr_action artifact" in caplog.text
    assert all(torch.equal(rebuilt.state_dict()[k], v) for k, v in reference.items())


def test_garbage_checkpoint_is_refused_by_the_loader(tmp_path: Path, runs_dir: Path) -> None:
    (tmp_path / "model.pt").write_bytes(b"not a checkpoint")
    model = new_model(compose_preset("mountaincar_va", runs_dir), "action", 1)
    with pytest.raises(CheckpointError, match="not a readable checkpoint"):
        load_weights(tmp_path / "model.pt", model, "repr.action")
    torch.save([torch.zeros(1)], tmp_path / "list.pt")
    with pytest.raises(CheckpointError, match="not hold a state dict"):
        load_weights(tmp_path / "list.pt", model, "repr.action")


def test_surface_under_the_car_heuristic_on_synthetic_frames() -> None:
    from plls_bench.repr.samples import CAR_COLS, CAR_ROWS, surface_under_car

    def frame(rgb: tuple[int, int, int]) -> np.ndarray:
        x = np.empty((3, 96, 96), dtype=np.uint8)
        x[:] = np.asarray(rgb, dtype=np.uint8)[:, None, None]
        x[:, 68:76, 46:50] = np.asarray([204, 0, 0], dtype=np.uint8)[:, None, None]  # the red car
        return x

    road, grass = frame((105, 105, 105)), frame((102, 204, 102))
    straddling = road.copy()
    straddling[:, CAR_ROWS, CAR_COLS.start:48] = grass[:, CAR_ROWS, CAR_COLS.start:48]
    assert list(surface_under_car(np.stack([road, grass, straddling]))) == ["road", "grass", "mixed"]
