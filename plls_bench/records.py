"""Committed run records: the small files of every non-smoke run, kept in git.

Run dirs (``results/runs/``) are git-ignored: they hold checkpoints, replay chunks and logs. A
record keeps what the results collector reads, nothing it does not: ``config.json``,
``status.json``, ``provenance.json``, ``metrics/``, ``samples/``, ``studies/`` and ``filmstrip/``.
Records live beside the runs dir (``results/records/`` for ``results/runs/``), in the same
``<experiment>/<variant>/seed=<k>`` layout, so a fresh clone regenerates ``results/`` from them and
a later smoke run cannot erase real-budget evidence. The collector reads both; a local run wins
over a record with the same key and config (see ``report/load.py``).

``python -m plls_bench.records [--runs results/runs] [--records DIR]`` exports every finished
non-smoke run; ``reproduce.sh`` does it after a non-smoke profile.
"""
from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from plls_bench.runs import STATUS_DONE, iter_run_dirs, read_json

RECORD_GLOBS = ("config.json", "status.json", "provenance.json", "metrics/*.jsonl", "metrics/*.json",
                "samples/*.npz", "studies/*.npz", "filmstrip/filmstrip.json", "filmstrip/frames.npz")
MAX_FILE_BYTES = 8 * 1024 * 1024  # a record file larger than this is not committed (logged)
EXCLUDED_BUDGETS = ("smoke",)     # smoke runs check the pipeline, not the paper


def records_dir_for(runs_dir: str | Path) -> Path:
    """The records folder beside a runs dir: ``results/runs`` -> ``results/records``."""
    return Path(runs_dir).parent / "records"


@dataclass(frozen=True)
class Exported:
    written: list[str]   # run keys (experiment/variant/seed=k) whose record was (re)written
    unchanged: int       # records already identical
    skipped: list[str]   # runs left out, with the reason


def record_files(run_dir: Path) -> list[Path]:
    """The files of ``run_dir`` that belong in its record (relative paths, sorted)."""
    found = {path.relative_to(run_dir) for pattern in RECORD_GLOBS for path in run_dir.glob(pattern)
             if path.is_file()}
    return sorted(found)


def export_run(run_dir: Path, target: Path) -> tuple[bool, list[str]]:
    """Copy ``run_dir``'s record files to ``target`` (replacing an older record whole, via a temp
    dir and rename). Returns (changed, files left out for size)."""
    files, too_big = [], []
    for rel in record_files(run_dir):
        size = (run_dir / rel).stat().st_size
        (too_big if size > MAX_FILE_BYTES else files).append(rel)
    if target.is_dir() and {p.relative_to(target) for p in target.rglob("*") if p.is_file()} == set(files) and all(
            (target / rel).read_bytes() == (run_dir / rel).read_bytes() for rel in files):
        return False, [str(r) for r in too_big]
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}."))
    try:
        for rel in files:
            (staging / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(run_dir / rel, staging / rel)
        if target.exists():
            old = target.with_name(f".{target.name}.old")
            target.rename(old)
            staging.rename(target)
            shutil.rmtree(old)
        else:
            staging.rename(target)
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)
    return True, [str(r) for r in too_big]


def export_records(runs_dir: str | Path, records_dir: str | Path | None = None) -> Exported:
    """Export every finished run of a non-smoke budget under ``runs_dir`` to ``records_dir``."""
    runs_root = Path(runs_dir)
    out = Path(records_dir) if records_dir is not None else records_dir_for(runs_root)
    written, skipped, unchanged = [], [], 0
    for run_dir in iter_run_dirs(runs_root):
        key = str(run_dir.relative_to(runs_root))
        config = (read_json(run_dir / "config.json") or {}).get("config") or {}
        budget = (config.get("budget") or {}).get("name")
        state = (read_json(run_dir / "status.json") or {}).get("state")
        if budget in EXCLUDED_BUDGETS or budget is None:
            continue
        if state != STATUS_DONE:
            skipped.append(f"{key}: status {state}")
            continue
        changed, too_big = export_run(run_dir, out / key)
        skipped += [f"{key}/{name}: over {MAX_FILE_BYTES // 2**20} MiB, not recorded" for name in too_big]
        if changed:
            written.append(key)
        else:
            unchanged += 1
    return Exported(written, unchanged, skipped)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plls_bench.records", description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", default="results/runs", help="root of the run directories (read only)")
    parser.add_argument("--records", default=None, help="records folder (default: 'records' beside --runs)")
    args = parser.parse_args(argv)
    if not Path(args.runs).is_dir():
        print(f"plls_bench.records: --runs {args.runs} is not a directory", file=sys.stderr)
        return 2
    done = export_records(args.runs, args.records)
    for key in done.written:
        print(f"[records] wrote {key}")
    for line in done.skipped:
        print(f"[records] skipped {line}")
    print(f"[records] {len(done.written)} written, {done.unchanged} unchanged, {len(done.skipped)} skipped")
    return 0


if __name__ == "__main__":
    sys.exit(main())
