"""What a DBC run needs to resume after a kill: agent, optimisers, RNGs, counters and the replay.

A checkpoint is ``checkpoints/dbc.pt`` (agent, optimisers, RNG states, the
:class:`~plls_bench.train.loop.Progress` as every checkpoint saves it
(:func:`~plls_bench.train.checkpoint.progress_record`) and ``replay_written``; a readable copy of
the progress in ``checkpoints/progress.json``) plus
``checkpoints/replay/chunk_<start>_<end>.npz``: each checkpoint appends only the replay slots
written since the previous one, so saving stays cheap as the buffer grows. Chunks are written
(atomically) before ``dbc.pt``; on resume, chunks past the checkpoint's slot count (from a
checkpoint interrupted half-way) are deleted, and chunks the ring buffer has since overwritten
are dropped as they become obsolete.
"""
from __future__ import annotations

import io
import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium.spaces import Box

from baselines.dbc import DBCAgent, FrameReplay
from plls_bench.config import Config
from plls_bench.core.atomic_files import read_json
from plls_bench.core.seeding import quiet_rng
from plls_bench.envs import make_vec_env
from plls_bench.repr.latent_wrappers import wrap_latent
from plls_bench.repr.pixel_trunk import conv_stack
from plls_bench.repr.store import Representations, load_representations
from plls_bench.rundirs.artifacts import load_npz, save_npz
from plls_bench.rundirs.composition import recorded_config
from plls_bench.rundirs.devices import resolve_device
from plls_bench.rundirs.run_dir import Run
from plls_bench.train.checkpoint import missing_checkpoint, progress_record, restored_progress
from plls_bench.train.loop import Progress

CHECKPOINT = "checkpoints/dbc.pt"
# The actor's weights alone (its conv trunk is the critic's, shared): what a record keeps of a
# finished DBC run to film it; dbc.pt with every module and optimiser is several times larger.
POLICY = "checkpoints/dbc_policy.pt"
PROGRESS = "checkpoints/progress.json"
REPLAY_DIR = "checkpoints/replay"
_CHUNK = re.compile(r"chunk_(\d+)_(\d+)\.npz")


def _chunks(run: Run) -> list[tuple[int, int, Path]]:
    found = []
    for path in (run.path / REPLAY_DIR).glob("chunk_*.npz"):
        match = _CHUNK.fullmatch(path.name)
        if match:
            found.append((int(match[1]), int(match[2]), path))
    return sorted(found)


def save_checkpoint(run: Run, agent: DBCAgent, replay: FrameReplay, progress: Progress,
                    rng: np.random.Generator) -> None:
    """Append the replay slots written since the last chunk as a new chunk, then write ``dbc.pt``
    atomically. The newest chunk on disk ends where the last checkpoint's slots ended: older
    chunks are dropped only once the ring buffer has overwritten them, never the newest."""
    saved_end = max((end for _, end, _ in _chunks(run)), default=0)
    start, end = max(saved_end, replay.oldest), replay.n_written
    if end > start:
        save_npz(run.path / REPLAY_DIR / f"chunk_{start:012d}_{end:012d}.npz", replay.export(start, end))
    saved = {**progress_record(progress), "replay_written": end}  # with the replay slots saved in chunks
    state = {"agent": agent.state_dict(), "progress": saved,
             "rng": rng.bit_generator.state, "torch_rng": torch.get_rng_state()}
    buffer = io.BytesIO()
    torch.save(state, buffer)
    run.write_bytes(CHECKPOINT, buffer.getvalue())
    run.write_json(PROGRESS, saved)  # a readable copy, written after the checkpoint
    for _, chunk_end, path in _chunks(run):  # slots the ring buffer no longer holds
        if chunk_end <= replay.oldest:
            path.unlink(missing_ok=True)


def load_checkpoint(run: Run, agent: DBCAgent, replay: FrameReplay,
                    rng: np.random.Generator) -> Progress | None:
    """Restore the last checkpoint into ``agent``, ``replay`` and ``rng``; None when there is none
    (then stale replay chunks of an earlier, uncheckpointed attempt are removed)."""
    path = run.path / CHECKPOINT
    if not path.exists():
        for _, _, chunk in _chunks(run):
            chunk.unlink()
        return None
    state: dict[str, Any] = torch.load(path, map_location=agent.device, weights_only=True)
    saved = state["progress"]
    progress = restored_progress(saved)  # DBC's checkpoints have always saved env_steps
    agent.load_state_dict(state["agent"])
    rng.bit_generator.state = state["rng"]
    torch.set_rng_state(state["torch_rng"].cpu())  # map_location moved it to the agent's device
    for start, end, chunk in _chunks(run):
        if end > saved["replay_written"]:  # written by a checkpoint that never completed
            chunk.unlink()
        else:
            replay.load(start, load_npz(chunk))
    if replay.n_written != saved["replay_written"]:
        raise RuntimeError(f"replay chunks in {run.path / REPLAY_DIR} hold {replay.n_written} slots, "
                           f"the checkpoint expects {saved['replay_written']}")
    return progress


def committed_files(run_path: Path) -> tuple[list[str], int] | None:
    """The run-relative files of the last checkpoint, ``dbc.pt`` (its commit point) last, and its
    iteration; None without one. What a partial record carries to resume the run elsewhere: its
    replay chunks (one interrupted half-way goes too and is dropped on resume, as after a kill)."""
    progress = read_json(Path(run_path) / PROGRESS)
    if progress is None or not (Path(run_path) / CHECKPOINT).is_file():
        return None
    chunks = [str(path.relative_to(run_path)) for _, _, path in _chunks(Run(run_path))]
    # an older progress record has no iteration
    return [*chunks, PROGRESS, CHECKPOINT], int(progress.get("iteration", progress["agent_steps"]))


def load_trained_agent(run_dir: Path, device: str = "auto") -> tuple[Config, DBCAgent, Box, Representations]:
    """A DBC run's typed config, its last checkpointed agent (no replay, no optimiser use), the
    box its actions map to (V_a's latent box with ``repr/action=vae``) and its V_a, for filmstrips.

    Everything lands on ``device`` (``auto``: a GPU when present), whatever device the run trained
    on; the returned config says so (``cfg.device``). Never trains: a missing V_a artifact raises
    ``MissingArtifact``. The task's env is made (not reset or rendered) only to read its spaces."""
    cfg = replace(recorded_config(run_dir), device=device)  # the recorded device may be absent here
    path = run_dir / CHECKPOINT if (run_dir / CHECKPOINT).exists() else run_dir / POLICY
    if not path.exists():
        raise missing_checkpoint(run_dir)
    target = resolve_device(device)  # refuses an absent GPU before any env is built
    assert cfg.algo.dbc is not None
    reprs = load_representations(cfg)
    venv = wrap_latent(make_vec_env(cfg.env, 1, 0), reprs)  # the spaces the agent saw in training
    try:
        obs_shape, space = venv.observation_space.shape, venv.action_space
    finally:
        venv.close()
    with quiet_rng(target):  # the agent's throw-away initial weights never draw from the global stream
        agent = DBCAgent(obs_shape, int(np.prod(space.shape)), cfg.algo.dbc, target, conv_stack(cfg.precision))
    state = torch.load(path, map_location=agent.device, weights_only=True)
    if path.name == Path(POLICY).name:  # a record's actor alone: acting needs nothing else
        agent.actor.load_state_dict(state)
    else:
        agent.load_state_dict(state["agent"])
    return cfg, agent, space, reprs


def policy_bytes(run_dir: Path) -> bytes | None:
    """The :data:`POLICY` file of the run's last checkpoint (the actor's state dict), or None
    without a checkpoint; ``load_trained_agent`` reads it when ``dbc.pt`` is absent."""
    path = Path(run_dir) / CHECKPOINT
    if not path.exists():
        return None
    # mmap: only the actor's storages are read, not the whole checkpoint (its replay is ~100 MiB)
    state = torch.load(path, map_location="cpu", weights_only=True, mmap=True)
    buffer = io.BytesIO()
    torch.save(state["agent"]["modules"]["actor"], buffer)
    return buffer.getvalue()


def policy_files(run_dir: Path) -> dict[str, bytes]:
    """What a record carries to rebuild the policy: the actor's weights alone (no replay); empty
    without a checkpoint. A record dir (no ``dbc.pt``) gives the :data:`POLICY` file it carries."""
    data = policy_bytes(run_dir)
    if data is None and (Path(run_dir) / POLICY).is_file():
        data = (Path(run_dir) / POLICY).read_bytes()
    return {} if data is None else {POLICY: data}
