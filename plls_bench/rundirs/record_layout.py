"""Where committed records live and what a record is, read without torch or simulators.

``results/records/`` (beside ``results/runs/``, :func:`records_dir_for`) holds::

    <experiment>/<variant>/seed=<k>/          the record of a finished run (status done)
    partial/<experiment>/<variant>/seed=<k>/  an unfinished run carried to the next session,
                                              with partial.json written last
    pending/<experiment>/<variant>/seed=<k>/  the metrics so far of an unfinished run whose
                                              checkpoint cannot be carried (pending.json):
                                              evidence only, never restored or judged
    artifacts/repr_{state,action}/<hash>/     the V_s / V_a models the records used, laid out as
                                              the runs dir's artifacts (key.json, meta.json)
"""
from __future__ import annotations

from pathlib import Path

from plls_bench.core.atomic_files import read_json
from plls_bench.rundirs.run_dir import STATUS_DONE, Run, stored_identity

# One cap for every committed file: a CarRacing V_s model.pt is 6.9 MiB, a DBC actor 11.9 MiB, a
# CarRacing PPO zip 3.4 MiB as a finished record carries it (no optimiser state) and 9.6 MiB with
# Adam's moments, as a partial record carries it. .ci/run fails on any tracked file over it.
MAX_FILE_BYTES = 16 * 1024 * 1024
# A partial record carries a whole checkpoint, so it is carried only while small: a stopped CNN PPO
# trial (its 9.6 MiB zip with Adam's moments and its metrics, about 10 MiB) fits. A stopped
# DBC-runner trial is never carried, whatever its size (RunnerSpec.snapshot_holds_replay: its
# snapshot holds a replay buffer; at reference sizes a pixel DBC's 116 MiB agent with optimisers
# plus its frame replay, 3.2 MiB per 1000 transitions, or a state SAC's 45 MiB dbc.pt, are over
# this cap too): it stays in its run dir on the machine that runs it, with its metrics so far
# written as a pending record. Carrying pixel DBC cost git history
# about 120 MiB per 3-hour sitting; every user of a clone paid for it. A file over MAX_FILE_BYTES
# still goes in parts (``<name>.part-<i>``) should the cap be raised, and older records in parts
# still restore.
MAX_PARTIAL_BYTES = 16 * 1024 * 1024
# What the tracked files under results/records may weigh together (.ci/run fails past it), sized for
# the quick profile's completion (measured 2026-12-05 at faf36b2: `git ls-files -z results/records |
# xargs -0 du -cb`, and the quick dry run's 64 pending trials). Today 135.6 MiB: 4 pixel DBC / PL-LS +
# DBC actors of 11.9 MiB (dbc_policy.pt: the actor's conv encoder and MLP trunk alone, 3.1 M fp32
# parameters) and 6 state-SAC actors of 4.1 MiB, 73 MiB; 6 CNN PPO zips without optimiser state,
# 20 MiB; V_s / V_a 8 MiB; MountainCar metrics and zips 1.2-1.8 MiB a trial. Finishing quick adds,
# per record as measured: 5 pixel actors (2 PL-LS + DBC, 3 pixel SAC, whose actor is DBC's)
# x 12.05 = 60.3; 9 CNN PPO (2 ppo, 2 ppo_va, 5 gSDE) x 3.41 = 30.7; 2 state SAC x 4.18 = 8.4;
# 5 MountainCar zoo x 1.47 = 7.4; 19 latent CarRacing PPO x 0.3 = 5.7; 3 cheetah V_a x 0.15 = 0.5
# (the 3 DBC, 1 PL-LS + DBC and 16 MountainCar re-runs replace records of their own size): 113 MiB,
# so about 249 MiB at completion, 57% of it DBC / SAC actors. 288 MiB leaves 39 MiB (16%): two
# stopped CNN PPO trials carried as partial records (10 MiB each, one per job of a 2-job sitting)
# and 19 MiB for the estimates' error. Recording the paper profile (30 CNN PPO trials, 13 pixel
# DBC / SAC actors: about 260 MiB of policies) needs a decision to raise it, not a silent growth
# of every clone.
RECORDS_BUDGET_BYTES = 288 * 1024 * 1024
PART_SUFFIX = ".part-"
EXCLUDED_BUDGETS = ("smoke",)  # smoke runs check the pipeline, not the paper
PARTIAL_DIR = "partial"
PARTIAL_MARKER = "partial.json"
PENDING_DIR = "pending"
PENDING_MARKER = "pending.json"
ARTIFACTS_DIR = "artifacts"
REPR_KINDS = ("repr_state", "repr_action")  # the artifacts records carry (datasets are too big)


def records_dir_for(runs_dir: str | Path) -> Path:
    """The records folder beside a runs dir: ``results/runs`` -> ``results/records``."""
    return Path(runs_dir).parent / "records"


def run_key(run_dir: str | Path, runs_dir: str | Path) -> Path | None:
    """``<experiment>/<variant>/seed=<k>`` of a run dir under ``runs_dir``; None elsewhere."""
    try:
        key = Path(run_dir).resolve().relative_to(Path(runs_dir).resolve())
    except ValueError:
        return None
    return key if len(key.parts) == 3 and key.parts[-1].startswith("seed=") else None


def layout_root(run_dir: str | Path) -> Path | None:
    """The root a run dir or record lives under by the ``<root>/<experiment>/<variant>/seed=<k>``
    layout (a runs dir, or a records dir whose ``artifacts/`` mirror the runs dir's); None otherwise."""
    path = Path(run_dir)
    return path.parents[2] if path.name.startswith("seed=") and len(path.parts) > 3 else None


def record_path(run_dir: str | Path) -> Path:
    """The record of a ``<runs_dir>/<experiment>/<variant>/seed=<k>`` run dir."""
    root = layout_root(run_dir)
    if root is None:
        raise ValueError(f"{run_dir} is not a <runs_dir>/<experiment>/<variant>/seed=<k> run dir")
    return records_dir_for(root) / Path(run_dir).relative_to(root)


def is_recorded(records_dir: str | Path, key: str | Path, cfg_hash: str) -> bool:
    """A committed record of ``key`` says done for this exact config."""
    return Run(Path(records_dir) / key).is_done(cfg_hash)


def partial_record(records_dir: str | Path, key: str | Path, cfg_hash: str) -> Path | None:
    """The complete partial record of ``key`` made with this config, or None."""
    path = Path(records_dir) / PARTIAL_DIR / key
    marker = read_json(path / PARTIAL_MARKER)
    if not isinstance(marker, dict):
        return None
    return path if stored_identity(path, marker.get("config_hash")) == cfg_hash else None


def partial_iteration(path: str | Path) -> int | None:
    """The iteration a partial record's checkpoint holds (its marker's), or None without one."""
    marker = read_json(Path(path) / PARTIAL_MARKER)
    return int(marker["iteration"]) if isinstance(marker, dict) and "iteration" in marker else None


def recorded_artifact(runs_dir: str | Path, kind: str, name: str) -> Path | None:
    """The complete copy of artifact ``<kind>/<name>`` in the records beside ``runs_dir``, or None."""
    path = records_dir_for(runs_dir) / ARTIFACTS_DIR / kind / name
    return path if read_json(path / "key.json") is not None else None


def runs_dir_of(run_dir: str | Path, recorded: str) -> str:
    """Where a trained run's V_s / V_a are looked up: the root it lives under (a record's are in
    its records dir's ``artifacts/``; a runs dir restores them from the records beside it), so a
    record made on another machine or checkout loads anywhere; ``recorded`` off the layout."""
    root = layout_root(run_dir)
    return recorded if root is None else str(root)


def done_record_hash(target: Path) -> str | None:
    """The config hash (today's rules) of the finished record at ``target`` ("None" if it stores no
    config); None when there is no finished record."""
    if (read_json(target / "status.json") or {}).get("state") != STATUS_DONE:
        return None
    return str(stored_identity(target))


def other_done_record(target: Path, ours: str | None) -> str | None:
    """``budget <name>, config <hash>`` of a finished record at ``target`` whose config hash is not
    ``ours`` (the run's); None when there is none (or it is this run's own)."""
    theirs = done_record_hash(target)
    if theirs is None or theirs == ours:
        return None
    budget = (((read_json(target / "config.json") or {}).get("config") or {}).get("budget") or {}).get("name")
    return f"budget {budget}, config {theirs}"
