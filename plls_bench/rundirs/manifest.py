"""A manifest of the code a run executes, to check a copy of it that has no ``.git``.

A GPU node or a container often gets the code by ``rsync``, without git, so its runs cannot read
their commit: ``provenance.json`` then takes it from ``$PLLS_BENCH_SOURCE_SHA``, on trust. This
module makes that checkable. In the checkout, ``python -m plls_bench.rundirs.manifest write > MANIFEST``
lists every tracked code file with its git blob hash; on the copy,
``export PLLS_BENCH_SOURCE_SHA=$(python -m plls_bench.rundirs.manifest check MANIFEST)`` prints the commit
only if every listed file is that blob and no unlisted code file sits beside them (else it names
the files on stderr and exits 1, so the export is empty and ``set -e`` stops the script).
"""
from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

from plls_bench.rundirs.provenance import REPO_ROOT, _git

# What decides a run's behaviour: the package, its configs, the bench scripts and the bootstrap.
CODE_PATHS = ("plls_bench", "conf", "bench", "pyproject.toml", "reproduce.sh")
CODE_SUFFIXES = (".py", ".yaml", ".json", ".toml", ".sh")  # an unlisted file of these kinds is code
HEADER = "commit "


class ManifestError(RuntimeError):
    """The manifest cannot be written or read as asked."""


def blob_hash(data: bytes) -> str:
    """Git's object id of a file's bytes (``git hash-object``), so no git is needed to check."""
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


def write_manifest(repo: Path = REPO_ROOT) -> str:
    """The manifest of HEAD's code files in the checkout ``repo``: a ``commit <sha>`` line, then
    ``<blob>\\t<path>`` per file. Refuses when the code has uncommitted changes (the copy would
    hold code the commit does not)."""
    def git(*args: str) -> str:
        out = _git(repo, *args)  # provenance's runner: None when git or the commit is missing
        if out is None:
            raise ManifestError(f"{repo} is not a git checkout with a commit (git {args[0]} failed)")
        return out
    changed = git("status", "--porcelain", "--untracked-files=no", "--", *CODE_PATHS).strip()
    if changed:
        raise ManifestError(f"uncommitted changes to the code: {changed.splitlines()[0].strip()} ...: "
                            "commit them first")
    rows = [line.split("\t", 1) for line in git("ls-tree", "-r", "HEAD", "--", *CODE_PATHS).splitlines()]
    files = [f"{meta.split()[2]}\t{path}" for meta, path in rows if meta.split()[1] == "blob"]
    return "\n".join([HEADER + git("rev-parse", "HEAD"), *files]) + "\n"


def read_manifest(text: str) -> tuple[str, dict[str, str]]:
    """(commit, {path: blob}) of a manifest's text."""
    lines = text.splitlines()
    if not lines or not lines[0].startswith(HEADER):
        raise ManifestError(f"not a manifest: its first line must be '{HEADER}<sha>'")
    try:
        blobs = {path: blob for blob, path in (line.split("\t", 1) for line in lines[1:] if line)}
    except ValueError as err:
        raise ManifestError("not a manifest: a file line must be '<blob>\\t<path>'") from err
    return lines[0][len(HEADER):], blobs


def check_copy(blobs: dict[str, str], root: Path) -> list[str]:
    """What in the copy at ``root`` is not the manifest's code: files that differ, are missing,
    or are code files the manifest does not list (caches and build output aside)."""
    problems = []
    for path, blob in sorted(blobs.items()):
        file = root / path
        if not file.is_file():
            problems.append(f"missing: {path}")
        elif blob_hash(file.read_bytes()) != blob:
            problems.append(f"differs: {path}")
    for top in CODE_PATHS:
        folder = root / top
        extra = folder.rglob("*") if folder.is_dir() else []
        for file in sorted(extra):
            rel = file.relative_to(root).as_posix()
            if file.is_file() and file.suffix in CODE_SUFFIXES and rel not in blobs and "__pycache__" not in rel:
                problems.append(f"not in the manifest: {rel}")
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plls_bench.rundirs.manifest", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("write", help="print the manifest of this checkout's HEAD")
    check = sub.add_parser("check", help="print the manifest's commit if the copy here holds exactly its code")
    check.add_argument("manifest", type=Path)
    check.add_argument("--root", type=Path, default=REPO_ROOT, help="the copy's root (default: this code's)")
    args = parser.parse_args(argv)
    try:
        if args.command == "write":
            sys.stdout.write(write_manifest())
            return 0
        if not args.manifest.is_file():
            raise ManifestError(f"manifest: no file at {args.manifest}")
        commit, blobs = read_manifest(args.manifest.read_text())
    except ManifestError as err:
        print(f"plls_bench.rundirs.manifest: {err}", file=sys.stderr)
        return 2
    problems = check_copy(blobs, args.root)
    print(f"manifest: {len(problems)} problem(s) in {len(blobs)} files of commit {commit[:10]}", file=sys.stderr)
    for line in problems:
        print(f"  {line}", file=sys.stderr)
    if problems:
        return 1
    print(commit)
    return 0


if __name__ == "__main__":
    sys.exit(main())
