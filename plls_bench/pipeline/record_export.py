"""Export runs into the committed records: finished runs, unfinished runs (partial records)
and the V_s / V_a artifacts they use. ``python -m plls_bench.records`` runs :func:`main`."""
from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from plls_bench.core.atomic_files import read_json
from plls_bench.pipeline.runner_registry import RUNNERS
from plls_bench.rundirs.record_layout import (
    ARTIFACTS_DIR,
    EXCLUDED_BUDGETS,
    MAX_FILE_BYTES,
    MAX_PARTIAL_BYTES,
    PART_SUFFIX,
    PARTIAL_DIR,
    PARTIAL_MARKER,
    PENDING_DIR,
    PENDING_MARKER,
    REPR_KINDS,
    done_record_hash,
    other_done_record,
    records_dir_for,
)
from plls_bench.rundirs.record_pending import pending_marker, reached_iteration, recorded_attempt
from plls_bench.rundirs.record_snapshot import Content, checkpoint_snapshot, record_files
from plls_bench.rundirs.run_dir import STATUS_DONE, iter_run_dirs, stored_identity

# Why a stopped run of a runner whose snapshot holds a replay buffer (DBC, pixel and state SAC) is
# never a partial record (RunnerSpec.snapshot_holds_replay): its metrics go to a pending record.
REPLAY_NOT_CARRIED = ("its snapshot holds a replay buffer: never carried; it resumes from its run dir on "
                      "the machine that runs it")

@dataclass
class Exported:
    written: list[str] = field(default_factory=list)    # run keys whose record was (re)written
    unchanged: int = 0                                    # records already identical
    skipped: list[str] = field(default_factory=list)    # runs or files left out, with the reason
    partial: list[str] = field(default_factory=list)    # unfinished runs written as partial records
    artifacts: list[str] = field(default_factory=list)  # <kind>/<hash> artifacts newly recorded
    held: list[str] = field(default_factory=list)       # finished runs kept as partial records (see export_records)
    pending: list[str] = field(default_factory=list)    # uncarried runs whose metrics went to pending records

    def summary(self) -> str:
        return (f"{len(self.written)} written, {self.unchanged} unchanged, {len(self.partial)} partial, "
                f"{len(self.pending)} pending, {len(self.held)} held, {len(self.artifacts)} artifact(s) added, "
                f"{len(self.skipped)} skipped")


def policy_files(run_dir: Path, runner: str | None) -> dict[str, Content]:
    """The files that rebuild the run's last checkpointed policy, as its runner declares them
    (``RunnerSpec.load_policy_files``; none for a runner that declares none, or an unknown one)."""
    spec = RUNNERS.get(runner or "")
    return {} if spec is None or spec.load_policy_files is None else dict(spec.load_policy_files()(run_dir))


def _size(content: Content) -> int:
    return len(content) if isinstance(content, bytes) else content.stat().st_size


def _bytes(content: Content) -> bytes:
    return content if isinstance(content, bytes) else content.read_bytes()


def write_record(target: Path, contents: dict[str, Content]) -> tuple[bool, list[str]]:
    """Write ``contents`` as the record at ``target`` (replacing an older one whole, via a temp
    dir and rename). Returns (changed, files left out for size)."""
    too_big = sorted(rel for rel, content in contents.items() if _size(content) > MAX_FILE_BYTES)
    files = {rel: content for rel, content in contents.items() if rel not in too_big}
    existing = {str(p.relative_to(target)) for p in target.rglob("*") if p.is_file()} if target.is_dir() else None
    if existing == set(files) and all((target / rel).read_bytes() == _bytes(c) for rel, c in files.items()):
        return False, too_big
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}."))
    try:
        for rel, content in files.items():
            (staging / rel).parent.mkdir(parents=True, exist_ok=True)
            (staging / rel).write_bytes(_bytes(content))
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
    return True, too_big


def _remove_unfinished(out: Path, kind: str, key: str) -> None:
    """Delete the ``kind`` (partial or pending) record ``key`` under ``out`` and the folders it
    leaves empty, so no empty ``<kind>/<experiment>/<variant>`` suggests a trial still unfinished."""
    shutil.rmtree(out / kind / key, ignore_errors=True)
    for folder in (out / kind / key).parents:
        if folder == out or not folder.is_dir() or any(folder.iterdir()):
            break
        folder.rmdir()


def export_run(run_dir: Path, target: Path) -> tuple[bool, list[str]]:
    """A finished run's record: the collector's files and its final policy checkpoint."""
    config = (read_json(run_dir / "config.json") or {}).get("config") or {}
    contents: dict[str, Content] = {str(rel): run_dir / rel for rel in record_files(run_dir)}
    return write_record(target, {**contents, **policy_files(run_dir, config.get("runner"))})


def split_parts(rel: str, content: Content) -> tuple[dict[str, bytes], dict[str, Any]]:
    """A file over the cap as parts ``<rel>.part-<i>`` of at most :data:`MAX_FILE_BYTES`, and what
    ``partial.json`` says of it: its parts in order, its size and sha256 (checked on restore)."""
    data = _bytes(content)
    parts = {f"{rel}{PART_SUFFIX}{i:03d}": data[start:start + MAX_FILE_BYTES]
             for i, start in enumerate(range(0, len(data), MAX_FILE_BYTES))}
    return parts, {"parts": list(parts), "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}


def export_partial(run_dir: Path, target: Path, config: dict[str, Any]) -> tuple[bool, list[str]] | str:
    """An unfinished run's partial record: its files so far, the last checkpoint that resumes it
    (``RunnerSpec.load_resume_files``; a file over the cap in parts) and ``partial.json`` (what to
    copy back, commit file last); a reason string when it cannot be carried: its runner's snapshot
    holds a replay buffer (``RunnerSpec.snapshot_holds_replay``), or it is over MAX_PARTIAL_BYTES."""
    spec = RUNNERS.get(config.get("runner") or "")
    if spec is None or spec.load_resume_files is None:
        return spec.not_carried if spec else f"runner {config.get('runner')!r} is not registered"
    if spec.snapshot_holds_replay:
        return REPLAY_NOT_CARRIED
    snapshot = checkpoint_snapshot(run_dir, spec.load_resume_files(), MAX_PARTIAL_BYTES)
    if isinstance(snapshot, str):
        return snapshot
    contents, files, iteration = snapshot
    restored = [rel for rel in contents if rel != "status.json"]
    split: dict[str, dict[str, Any]] = {}
    for rel in [rel for rel, content in contents.items() if _size(content) > MAX_FILE_BYTES]:
        parts, split[rel] = split_parts(rel, contents.pop(rel))
        contents.update(parts)
    state = (read_json(run_dir / "status.json") or {}).get("state")
    marker = {"config_hash": stored_identity(run_dir), "state": state,
              "iteration": iteration, "files": restored, "split": split, "commit": files[-1]}
    contents[PARTIAL_MARKER] = (json.dumps(marker, indent=2, sort_keys=True) + "\n").encode()
    return write_record(target, contents)


def export_pending(run_dir: Path, target: Path, not_carried: str,
                   config_hash: str | None) -> tuple[bool, list[str]] | str | None:
    """An uncarried run's pending record (``records.pending``): its record files and
    ``pending.json``. None when it has no metrics row yet; a reason string when the record already
    holds an attempt of this config that got further (a trial restarted from zero elsewhere)."""
    reached = reached_iteration(run_dir)
    if reached is None:
        return None
    earlier = recorded_attempt(target, config_hash)
    if earlier is not None and earlier > reached:
        return (f"its pending record is kept: an earlier attempt reached iteration {earlier:,}, "
                f"this run {reached:,}")
    marker = pending_marker(run_dir, config_hash, reached, not_carried)
    contents: dict[str, Content] = {str(rel): run_dir / rel for rel in record_files(run_dir)}
    contents[PENDING_MARKER] = (json.dumps(marker, indent=2, sort_keys=True) + "\n").encode()
    return write_record(target, contents)


def artifact_names(config: dict[str, Any]) -> list[tuple[str, str]]:
    """(kind, hash) of the V_s / V_a artifacts a run's config uses."""
    from plls_bench.repr.keys import KINDS, model_config, repr_path
    from plls_bench.rundirs.composition import config_from_dict

    cfg = config_from_dict(config)
    return [(KINDS[w], repr_path(cfg, w).name) for w in ("state", "action") if model_config(cfg, w).kind == "vae"]


def export_artifact(runs_root: Path, out: Path, kind: str, name: str) -> tuple[bool, list[str]] | None:
    """Copy a complete runs-dir artifact (all its files, each under the cap) into the records;
    None when it is not built here. Nothing is written when a file is over the cap."""
    source = runs_root / ARTIFACTS_DIR / kind / name
    if kind not in REPR_KINDS or read_json(source / "key.json") is None:
        return None
    contents: dict[str, Content] = {str(p.relative_to(source)): p for p in sorted(source.rglob("*")) if p.is_file()}
    too_big = [rel for rel, p in contents.items() if _size(p) > MAX_FILE_BYTES]
    if too_big:
        return False, too_big
    return write_record(out / ARTIFACTS_DIR / kind / name, contents)


def export_records(runs_dir: str | Path, records_dir: str | Path | None = None, replace: bool = False) -> Exported:
    """Export every run of a non-smoke budget under ``runs_dir`` to ``records_dir``: finished ones
    as records (a partial record of the same run is then removed), unfinished runs as partial
    records, and the V_s / V_a artifacts of both, once each.

    A record slot is ``<experiment>/<variant>/seed=<k>``, whatever the budget. A finished run whose
    slot holds a finished record of another config (a paper-budget trial where a quick one is
    recorded) never replaces it unless ``replace``: it is held as a partial record instead, which
    the next launch of its config restores as done, so neither trial is lost."""
    runs_root = Path(runs_dir)
    out = Path(records_dir) if records_dir is not None else records_dir_for(runs_root)
    done, used = Exported(), set()
    for run_dir in iter_run_dirs(runs_root):
        key = str(run_dir.relative_to(runs_root))
        written = read_json(run_dir / "config.json") or {}
        config = written.get("config") or {}
        if (config.get("budget") or {}).get("name") in (*EXCLUDED_BUDGETS, None):
            continue
        state, ours = (read_json(run_dir / "status.json") or {}).get("state"), stored_identity(run_dir)
        if state != STATUS_DONE and ours is not None and done_record_hash(out / key) == ours:
            done.skipped.append(f"{key}: status {state} (its record holds this trial, finished)")
            continue  # a stale copy of a trial finished elsewhere: a partial record would only shadow it
        other = None if replace or state != STATUS_DONE else other_done_record(out / key, ours)
        if state == STATUS_DONE and other is None:
            _count(done, key, export_run(run_dir, out / key), done.written)
            for kind in (PARTIAL_DIR, PENDING_DIR):  # the finished record replaces them
                _remove_unfinished(out, kind, key)
        else:
            carried = export_partial(run_dir, out / PARTIAL_DIR / key, config)
            if isinstance(carried, str):
                done.skipped.append(f"{key}: status {state} ({carried})")
                _count_pending(done, key, export_pending(run_dir, out / PENDING_DIR / key, carried, ours))
                continue
            _count(done, key, carried, done.partial)
            if (recorded_attempt(out / PENDING_DIR / key, ours) or 0) <= (reached_iteration(run_dir) or 0):
                _remove_unfinished(out, PENDING_DIR, key)  # the partial record holds its metrics too
            if other is not None:
                done.held.append(f"{key}: its record holds a finished trial of another config ({other}); "
                                 "held as a partial record (--replace replaces the record)")
        try:
            used.update(artifact_names(config))
        except Exception as err:  # a config this version no longer reads: say so, export the rest
            done.skipped.append(f"{key}: V_s / V_a not identified ({type(err).__name__}: {err})")
    for kind, name in sorted(used):
        result = export_artifact(runs_root, out, kind, name)
        if result is not None:
            _count(done, f"{kind}/{name}", result, done.artifacts, unchanged=False)
    return done


def _count(done: Exported, key: str, result: tuple[bool, list[str]], written: list[str],
           unchanged: bool = True) -> None:
    changed, too_big = result
    done.skipped += [f"{key}/{name}: over {MAX_FILE_BYTES // 2**20} MiB, not recorded" for name in too_big]
    if changed:
        written.append(key)
    elif unchanged:
        done.unchanged += 1


def _count_pending(done: Exported, key: str, result: tuple[bool, list[str]] | str | None) -> None:
    if result is None:
        return
    if isinstance(result, str):
        done.skipped.append(f"{key}: no pending record written ({result})")
    else:
        _count(done, key, result, done.pending)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plls_bench.records",
                                     description="Export finished and unfinished non-smoke runs into the "
                                                 "committed records (docs/results.md: Results collector).")
    parser.add_argument("--runs", default="results/runs", help="root of the run directories (read only)")
    parser.add_argument("--records", default=None, help="records folder (default: 'records' beside --runs)")
    parser.add_argument("--replace", action="store_true",
                        help="let a finished run replace a finished record of another config in its slot "
                             "(default: hold it as a partial record)")
    args = parser.parse_args(argv)
    if not Path(args.runs).is_dir():
        print(f"plls_bench.records: --runs {args.runs} is not a directory", file=sys.stderr)
        return 2
    done = export_records(args.runs, args.records, replace=args.replace)
    for line in done.held:
        print(f"[records] held {line}")
    for key in done.written:
        print(f"[records] wrote {key}")
    for key in done.partial:
        print(f"[records] wrote partial record {key} (resumed from there by the next start)")
    for key in done.pending:
        print(f"[records] wrote pending record {key} (its metrics so far; its checkpoint stays in the run dir)")
    for name in done.artifacts:
        print(f"[records] wrote artifact {name}")
    for line in done.skipped:
        print(f"[records] skipped {line}")
    print(f"[records] {done.summary()}")
    return 0
