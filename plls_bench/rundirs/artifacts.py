"""Content-addressed artifacts shared by all trials: datasets and trained representations.

An artifact lives at ``<runs_dir>/artifacts/<kind>/<hash>/`` where ``hash`` is derived from the
JSON ``key`` that fully determines its content. It is built once, under a file lock, into a
temporary directory that is renamed into place when complete, so a reader never sees a
half-built artifact and two processes asking for the same one build it once.
"""
from __future__ import annotations

import os
import shutil
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path
from typing import Any

import numpy as np
from filelock import FileLock

from plls_bench.core.atomic_files import atomic_write_bytes, atomic_write_json, read_json
from plls_bench.core.hashing import stable_hash

KEY_FILE = "key.json"


@dataclass(frozen=True)
class Artifact:
    path: Path      # the complete artifact directory
    built: bool     # True when this call built it, False when it already existed


def artifact_root(runs_dir: str | Path, kind: str) -> Path:
    return Path(runs_dir) / "artifacts" / kind


def artifact_path(runs_dir: str | Path, kind: str, key: dict[str, Any]) -> Path:
    return artifact_root(runs_dir, kind) / stable_hash(key)


def get_or_build(runs_dir: str | Path, kind: str, key: dict[str, Any],
                 build: Callable[[Path], None]) -> Artifact:
    """Return the artifact for ``key``, calling ``build(tmp_dir)`` first if it does not exist.

    ``build`` writes the artifact's files into ``tmp_dir``; on success the directory is renamed
    to its content address. If ``build`` raises, nothing is left behind.
    """
    final = artifact_path(runs_dir, kind, key)
    if _is_complete(final):
        return Artifact(final, built=False)
    final.parent.mkdir(parents=True, exist_ok=True)
    with FileLock(str(final) + ".lock"):
        if _is_complete(final):
            return Artifact(final, built=False)
        if final.exists():  # a directory without its key file cannot be trusted: rebuild
            discard(final)
        for stale in final.parent.glob(f".{final.name}.tmp-*"):
            shutil.rmtree(stale, ignore_errors=True)
        tmp = final.parent / f".{final.name}.tmp-{os.getpid()}"
        tmp.mkdir()
        try:
            build(tmp)
            atomic_write_json(tmp / KEY_FILE, key)
            os.rename(tmp, final)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
    return Artifact(final, built=True)


def is_built(runs_dir: str | Path, kind: str, key: dict[str, Any]) -> bool:
    """Whether the artifact for ``key`` exists, complete."""
    return _is_complete(artifact_path(runs_dir, kind, key))


def discard(path: Path) -> None:
    """Remove a corrupt artifact so the next request rebuilds it (caller holds the lock or
    accepts a rebuild race, which the rename in :func:`get_or_build` makes safe)."""
    trash = path.parent / f".{path.name}.trash-{os.getpid()}"
    os.rename(path, trash)
    shutil.rmtree(trash, ignore_errors=True)


def _is_complete(path: Path) -> bool:
    return read_json(path / KEY_FILE) is not None


# --------------------------------------------------------------------------- deterministic npz
_EPOCH = (1980, 1, 1, 0, 0, 0)  # fixed zip timestamps: same arrays -> byte-identical file


def save_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` as a compressed ``.npz`` that is byte-identical for identical inputs
    (numpy's own savez stamps the current time into the zip), atomically."""
    atomic_write_bytes(path, npz_bytes(arrays))


def npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """The bytes of :func:`save_npz`'s file (for ``Run.write_bytes`` into a run directory)."""
    buffer = BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for name in sorted(arrays):
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_EPOCH)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            with archive.open(info, "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.ascontiguousarray(arrays[name]), allow_pickle=False)
    return buffer.getvalue()


def load_npz(path: Path) -> dict[str, np.ndarray]:
    """Load every array of an ``.npz`` (no pickles)."""
    with np.load(path, allow_pickle=False) as data:
        return {name: data[name] for name in data.files}
