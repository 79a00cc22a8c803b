"""PPO checkpoints: the SB3 model (weights and Adam state), RNG states and training progress;
and the progress record every trainer's checkpoint holds (:func:`progress_record`, DBC's too).

Layout under ``<run>/checkpoints/``::

    ppo-<iteration>.zip   stable-baselines3's own format (``PPO.load`` reads it)
    vecnormalize-<iteration>.json  VecNormalize statistics, only with algo.ppo.normalize_*
    latest.json           written last and atomically: the commit point of a checkpoint

``latest.json`` holds the progress (:func:`progress_record`), the RNG states of python, numpy's
global generator (SB3 shuffles minibatches with it) and torch (action sampling), and names the zip
it belongs to. A kill at any moment leaves the previous ``latest.json`` and its
zip intact; older files are deleted only after the new ``latest.json`` is in place.
"""
from __future__ import annotations

import base64
import random
import zipfile
from dataclasses import asdict, fields
from io import BytesIO
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO

from plls_bench.core.atomic_files import atomic_write_bytes, read_json
from plls_bench.rundirs.run_dir import Run
from plls_bench.train.loop import Progress

LATEST = "latest.json"
# Rollout leftovers are not needed: a resumed run resets its training envs (see ppo.py).
_NOT_SAVED = ["_last_obs", "_last_episode_starts", "_last_original_obs"]
OPTIMIZER_ENTRY = "policy.optimizer.pth"  # SB3's zip entry for the optimiser's state_dict


def progress_record(progress: Progress) -> dict[str, Any]:
    """What a checkpoint keeps of ``progress``: all of it, for PPO (``latest.json``) and DBC
    (``dbc.pt``, ``progress.json``) alike; read back with :func:`restored_progress`."""
    return asdict(progress)


def restored_progress(saved: dict[str, Any], action_repeat: int | None = None) -> Progress:
    """The :class:`Progress` a checkpoint saved. Checkpoints written before :func:`progress_record`
    held part of it, and the rest follows: DBC's lacked ``iteration`` (its agent step); PPO's held
    (iteration, agent_steps, wall_s), so env steps are agent steps x ``action_repeat`` (needed only
    there), PPO's trainer recounts ``evaluations`` from its schedule and never counts ``episodes``."""
    values = {f.name: saved[f.name] for f in fields(Progress) if f.name in saved}
    values.setdefault("iteration", values["agent_steps"])
    if "env_steps" not in values:
        if action_repeat is None:
            raise ValueError("the checkpoint saved no env_steps: restoring it needs the env's action_repeat")
        values["env_steps"] = values["agent_steps"] * action_repeat
    return Progress(**values)


def missing_checkpoint(run_dir: str | Path) -> FileNotFoundError:
    """The error of a trained policy asked of a run dir without a committed checkpoint."""
    return FileNotFoundError(f"{run_dir}/checkpoints has no committed checkpoint")


def rng_state() -> dict[str, Any]:
    """JSON-able states of python's, numpy's global and torch's CPU generators."""
    kind, keys, pos, has_gauss, gauss = np.random.get_state()
    version, internal, gauss_next = random.getstate()
    return {"python": [version, list(internal), gauss_next],
            "numpy": [kind, keys.tolist(), pos, has_gauss, gauss],
            "torch": base64.b64encode(torch.get_rng_state().numpy().tobytes()).decode()}


def set_rng_state(state: dict[str, Any]) -> None:
    version, internal, gauss_next = state["python"]
    random.setstate((version, tuple(internal), gauss_next))
    kind, keys, pos, has_gauss, gauss = state["numpy"]
    np.random.set_state((kind, np.asarray(keys, dtype=np.uint32), pos, has_gauss, gauss))
    raw = np.frombuffer(base64.b64decode(state["torch"]), dtype=np.uint8).copy()
    torch.set_rng_state(torch.from_numpy(raw))


def save(run: Run, model: PPO, progress: Progress, normalization: bytes | None = None) -> None:
    """Checkpoint ``model`` (and VecNormalize statistics, when given) at ``progress``; committed
    when ``latest.json`` is replaced."""
    name = f"ppo-{progress.iteration:07d}.zip"
    buffer = BytesIO()
    model.save(buffer, exclude=_NOT_SAVED)
    atomic_write_bytes(run.checkpoints_dir / name, buffer.getvalue())
    stats = None
    if normalization is not None:
        stats = f"vecnormalize-{progress.iteration:07d}.json"
        atomic_write_bytes(run.checkpoints_dir / stats, normalization)
    run.write_json(f"checkpoints/{LATEST}", {"model": name, "normalization": stats,
                                             "progress": progress_record(progress), "rng": rng_state()})
    for old in [*run.checkpoints_dir.glob("ppo-*.zip"), *run.checkpoints_dir.glob("vecnormalize-*.json")]:
        if old.name not in (name, stats):
            old.unlink(missing_ok=True)


def latest(run_path: Path) -> tuple[Path, dict[str, Any], dict[str, Any]] | None:
    """The last committed checkpoint: (model zip, saved progress for :func:`restored_progress`,
    rng state), or None."""
    record = read_json(Path(run_path) / "checkpoints" / LATEST)
    if record is None:
        return None
    zip_path = Path(run_path) / "checkpoints" / record["model"]
    if not zip_path.is_file():
        raise FileNotFoundError(f"{zip_path} named by {LATEST} is missing; the checkpoint is corrupt")
    return zip_path, record["progress"], record["rng"]


def normalization(run_path: Path) -> bytes | None:
    """The VecNormalize statistics of the last committed checkpoint, or None (normalisation off,
    or a checkpoint written before the suite had it)."""
    record = read_json(Path(run_path) / "checkpoints" / LATEST)
    name = (record or {}).get("normalization")
    if not name:
        return None
    path = Path(run_path) / "checkpoints" / name
    if not path.is_file():
        raise FileNotFoundError(f"{path} named by {LATEST} is missing; the checkpoint is corrupt")
    return path.read_bytes()


def committed_files(run_path: Path) -> tuple[list[str], int] | None:
    """The run-relative files of the last committed checkpoint, ``latest.json`` (its commit
    point) last, and its iteration; None without one. What a record carries to rebuild the
    policy (``load_trained``) or resume the run."""
    record = read_json(Path(run_path) / "checkpoints" / LATEST)
    if record is None:
        return None
    names = [record["model"], *([record["normalization"]] if record.get("normalization") else []), LATEST]
    return [f"checkpoints/{name}" for name in names], int(record["progress"]["iteration"])


def policy_files(run_path: Path) -> dict[str, Path | bytes]:
    """Run-relative name -> content of the files that rebuild the last checkpointed policy
    (:func:`committed_files`), the model zip without its optimiser state; empty without a checkpoint."""
    found = committed_files(run_path)
    if found is None:
        return {}
    files: dict[str, Path | bytes] = {rel: Path(run_path) / rel for rel in found[0]}
    model = found[0][0]  # the zip comes first
    if files[model].is_file():  # a missing zip stays a path: its reader says so, as for any file here
        files[model] = without_optimizer_state(files[model].read_bytes())
    return files


def without_optimizer_state(zip_bytes: bytes) -> bytes:
    """An SB3 zip whose Adam state keeps its settings but no moments: about a third of a CarRacing
    CNN zip's size (3.4 of 9.6 MiB). ``PPO.load`` still reads it (the optimiser would start
    afresh), which is all that acting, evaluating and filming need; resuming training does not use
    it (a partial record carries the whole zip). Entries keep their order and dates, so the same
    zip always gives the same bytes, and a stripped zip strips to itself. Bytes that are no zip
    are returned as they are (loading them fails as it would have)."""
    if not zipfile.is_zipfile(BytesIO(zip_bytes)):
        return zip_bytes
    out = BytesIO()
    with zipfile.ZipFile(BytesIO(zip_bytes)) as source, zipfile.ZipFile(out, "w") as target:
        for info in source.infolist():
            data = source.read(info)
            if info.filename == OPTIMIZER_ENTRY:
                saved = torch.load(BytesIO(data), map_location="cpu", weights_only=True)
                buffer = BytesIO()
                torch.save({"state": {}, "param_groups": saved["param_groups"]}, buffer)
                data = buffer.getvalue()
            target.writestr(info, data)
    return out.getvalue()
