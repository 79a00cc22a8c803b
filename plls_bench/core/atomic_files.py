"""Files that must survive a kill: atomic writes (temp file, fsync, rename), tolerant JSON reads,
and JSONL streams whose torn or corrupt lines are counted, never fatal. Everything that writes a
run, a record or a report goes through here (``runs.Run`` for run directories)."""
from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` via a temp file in the same directory, fsync and rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_json(path: Path, obj: Any) -> None:
    atomic_write_bytes(path, (json.dumps(obj, indent=2, sort_keys=True, default=str) + "\n").encode())


def read_json(path: Path) -> Any | None:
    """The parsed JSON at ``path``, or None when it is missing or unreadable."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


def jsonl_line(record: dict[str, Any]) -> str:
    """The one format of a metrics line: sorted keys, numpy scalars as floats, newline-ended."""
    return json.dumps(record, sort_keys=True, default=float) + "\n"


def append_jsonl(path: Path, record: dict[str, Any]) -> None:
    """Append one line-complete JSON record (one write call, flushed and fsynced)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "ab") as handle:
        handle.write(jsonl_line(record).encode())
        handle.flush()
        os.fsync(handle.fileno())


@dataclass(frozen=True)
class JsonlScan:
    """What a jsonl file holds: its complete records and what had to be skipped."""

    records: list[Any]
    corrupt_lines: tuple[int, ...]  # 1-based numbers of complete lines that are not valid JSON
    torn_tail: bool                 # the last line has no newline: a kill mid-write


def scan_jsonl(path: Path) -> JsonlScan | None:
    """Parse ``path`` line by line, keeping account of skipped lines; None when it is missing or
    unreadable. The results collector uses this to report damage that :func:`read_jsonl` hides."""
    try:
        text = Path(path).read_text()
    except (OSError, UnicodeDecodeError):
        return None
    records: list[Any] = []
    corrupt: list[int] = []
    torn = False
    for number, line in enumerate(text.splitlines(keepends=True), 1):
        if not line.endswith("\n"):
            torn = True
            break
        try:
            records.append(json.loads(line))
        except ValueError:
            corrupt.append(number)
    return JsonlScan(records, tuple(corrupt), torn)


def read_jsonl(path: Path) -> list[dict[str, Any]]:
    """All complete records; a torn last line (a kill mid-write) or a corrupt line is skipped."""
    scan = scan_jsonl(path)
    return scan.records if scan is not None else []
