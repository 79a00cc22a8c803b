"""Pending records: the metrics so far of an unfinished trial whose checkpoint cannot be carried.

A pixel DBC trial's agent with its optimisers (116 MiB) and its frame replay (3.2 MiB per 1000
transitions), or a state-SAC trial's 45 MiB ``dbc.pt``, are over
:data:`~plls_bench.rundirs.record_layout.MAX_PARTIAL_BYTES` (16 MiB: stopped CNN PPO trials fit), so its
run dir resumes it only on the machine that holds it. Its curve need not be lost with that machine: ``python -m
plls_bench.records`` writes ``pending/<experiment>/<variant>/seed=<k>/`` with the record files
(``config.json``, ``status.json``, ``provenance.json``, ``metrics/``) and ``pending.json`` (the
iteration its rows reach, why the checkpoint stayed behind). A pending record is evidence only: no
run resumes from it, the collector judges nothing from it, and the dry run names it when its trial
has to start again (``reproduce --dry-run``).

One rule keeps the furthest evidence: a run that is behind the pending record of its own config
(a trial restarted from zero on a new machine) leaves the record as it is until it passes it,
whether the run itself goes to a pending or a partial record.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from plls_bench.core.atomic_files import read_json, read_jsonl
from plls_bench.rundirs.record_layout import PENDING_MARKER
from plls_bench.rundirs.run_dir import stored_identity

STREAMS = ("train", "eval")  # metrics/<stream>.jsonl rows carry the iteration they were logged at


def reached_iteration(run_dir: Path) -> int | None:
    """The furthest iteration any complete row of the run's ``metrics/{train,eval}.jsonl`` names;
    None when there is no such row yet."""
    rows = [row for stream in STREAMS for row in read_jsonl(Path(run_dir) / "metrics" / f"{stream}.jsonl")]
    return max((row["iteration"] for row in rows if isinstance(row, dict) and isinstance(row.get("iteration"), int)),
               default=None)


def recorded_attempt(target: Path, cfg_hash: str | None) -> int | None:
    """The iteration the pending record at ``target`` reached when it holds this config; else None."""
    marker = read_json(Path(target) / PENDING_MARKER)
    if not isinstance(marker, dict) or stored_identity(target, marker.get("config_hash")) != cfg_hash:
        return None
    return int(marker["iteration"])


def pending_marker(run_dir: Path, cfg_hash: str | None, reached: int, reason: str) -> dict[str, Any]:
    """What ``pending.json`` says: the run's config hash and state, the iteration its rows reach and
    why its checkpoint was not carried."""
    state = (read_json(Path(run_dir) / "status.json") or {}).get("state")
    return {"config_hash": cfg_hash, "state": state, "iteration": reached,
            "resumable": False, "not_carried": reason}
