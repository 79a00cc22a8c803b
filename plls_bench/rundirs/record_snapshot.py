"""Reading a run's files for its record: the collector's files, and an unfinished run's last
checkpoint read consistently while the run may still be writing the next one."""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

RECORD_GLOBS = ("config.json", "status.json", "provenance.json", "metrics/*.jsonl", "metrics/*.json",
                "samples/*.npz", "studies/*.npz", "filmstrip/filmstrip.json", "filmstrip/frames.npz")
Content = Path | bytes  # a file of the run, or bytes made from it
# run dir -> its last checkpoint's files (commit file last) and iteration; a runner's
# ``RunnerSpec.load_resume_files()``
ResumeFiles = Callable[[Path], "tuple[list[str], int] | None"]
# Reads of an unfinished run's checkpoint before its export gives up (checkpoint_snapshot): a
# checkpoint lands every few minutes and a read takes about a second, so a second read succeeds.
SNAPSHOT_TRIES = 3


def record_files(run_dir: Path) -> list[Path]:
    """The collector's files of ``run_dir`` that belong in its record (relative paths, sorted)."""
    found = {path.relative_to(run_dir) for pattern in RECORD_GLOBS for path in run_dir.glob(pattern)
             if path.is_file()}
    return sorted(found)


def _stamp(path: Path) -> tuple[int, int, int]:
    """What changes when a file is rewritten, atomically (a new inode) or in place."""
    stat = path.stat()
    return stat.st_ino, stat.st_size, stat.st_mtime_ns


def checkpoint_snapshot(run_dir: Path, resume_files: ResumeFiles,
                        max_bytes: int) -> tuple[dict[str, Content], list[str], int] | str:
    """The run's record files and its last checkpoint's files (commit file last) read into
    memory, and the checkpoint's iteration; a reason string when there is none, when all of it is
    over ``max_bytes``, or when it kept changing. A run still training commits a checkpoint every
    few minutes; one committed mid-read would pair a new commit file with an older replay chunk
    list, or metrics older than the checkpoint (rows lost on resume). So the read is repeated until
    the checkpoint's files and commit file are the same after it as before, at most
    :data:`SNAPSHOT_TRIES` times."""
    for _ in range(SNAPSHOT_TRIES):
        found = resume_files(run_dir)
        if found is None:
            return "no checkpoint to carry"
        files, iteration = found
        paths = {str(rel): run_dir / rel for rel in record_files(run_dir)} | {rel: run_dir / rel for rel in files}
        try:
            stamp = _stamp(run_dir / files[-1])
            total = sum(path.stat().st_size for path in paths.values())
            if total > max_bytes:  # a run resumed without one of them would lose its rows or its checkpoint
                return f"{total / 2**20:.1f} MiB to carry, over the {max_bytes // 2**20} MiB of a partial record"
            contents: dict[str, Content] = {rel: path.read_bytes() for rel, path in paths.items()}
            if resume_files(run_dir) == found and _stamp(run_dir / files[-1]) == stamp:
                return contents, files, iteration
        except FileNotFoundError:  # a file went mid-read (a replay chunk the ring buffer dropped)
            continue
    return (f"its checkpoint changed during each of {SNAPSHOT_TRIES} reads (a run still training); "
            "export after it stops")
