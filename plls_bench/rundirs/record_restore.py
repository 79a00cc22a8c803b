"""Bring committed records back into a runs dir: a partial record seeds its run dir so the trial
resumes where the last session stopped; a recorded artifact's files fill a runs-dir artifact.

Both copy file by file with atomic writes; what makes the copy count is written last (a partial
record's checkpoint commit file, an artifact's ``key.json`` via ``artifacts.get_or_build``), so a
copy cut off half-way is never taken for complete.
"""
from __future__ import annotations

import hashlib
import shutil
from pathlib import Path
from typing import Any

from plls_bench.core.atomic_files import atomic_write_bytes, read_json
from plls_bench.rundirs.artifacts import KEY_FILE
from plls_bench.rundirs.record_layout import PARTIAL_MARKER, partial_record, records_dir_for, run_key


def copy_artifact_files(source: Path, out: Path) -> None:
    """An ``artifacts.get_or_build`` build step: the recorded artifact's files, less its key file
    (``get_or_build`` writes that last)."""
    for path in sorted(source.rglob("*")):
        if path.is_file() and path.name != KEY_FILE:
            (out / path.relative_to(source)).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, out / path.relative_to(source))


def seed_from_partial(run_dir: str | Path, runs_dir: str | Path, cfg_hash: str) -> tuple[Path, int] | None:
    """Copy the partial record of this trial (same config hash) into ``run_dir`` when the run dir
    has no committed checkpoint of its own; returns (record, iteration) or None. The record's
    checkpoint commit file is copied last; metrics rows past the checkpoint are dropped by the
    trainer's resume (``train.loop``), as after a kill."""
    key = run_key(run_dir, runs_dir)
    source = None if key is None else partial_record(records_dir_for(runs_dir), key, cfg_hash)
    if source is None:
        return None
    marker = read_json(source / PARTIAL_MARKER)
    if (Path(run_dir) / marker["commit"]).exists():
        return None  # the local checkpoint is this machine's own, at least as recent
    files = [f for f in marker["files"] if f != marker["commit"]] + [marker["commit"]]
    split = marker.get("split", {})
    for rel in files:
        data = joined_parts(source, rel, split[rel]) if rel in split else (source / rel).read_bytes()
        atomic_write_bytes(Path(run_dir) / rel, data)
    return source, int(marker["iteration"])


def joined_parts(source: Path, rel: str, split: dict[str, Any]) -> bytes:
    """A file a partial record holds in parts (``export.split_parts``), joined and checked."""
    data = b"".join((source / part).read_bytes() for part in split["parts"])
    if len(data) != split["bytes"] or hashlib.sha256(data).hexdigest() != split["sha256"]:
        raise RuntimeError(f"partial record {source}: the parts of {rel} do not join to the file it recorded "
                           f"({split['bytes']} bytes, sha256 {split['sha256'][:12]}...); restore the record from "
                           "git, or delete it to start the trial afresh")
    return data
