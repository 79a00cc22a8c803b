"""The code manifest: a copy without .git gets its commit only if it holds exactly that code."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from plls_bench.rundirs.manifest import ManifestError, blob_hash, check_copy, main, read_manifest, write_manifest


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True, check=True).stdout


@pytest.fixture
def checkout(tmp_path: Path) -> Path:
    """A git checkout with code under two of the manifest's paths, and a non-code folder."""
    repo = tmp_path / "repo"
    for rel, text in {"plls_bench/a.py": "A = 1\n", "plls_bench/sub/b.py": "B = 2\n",
                      "conf/config.yaml": "seed: 0\n", "docs/notes.md": "not code\n"}.items():
        (repo / rel).parent.mkdir(parents=True, exist_ok=True)
        (repo / rel).write_text(text)
    _git(repo.parent, "init", "-q", str(repo))
    _git(repo, "add", ".")
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", "code")
    return repo


def _copy(repo: Path, dest: Path) -> Path:
    shutil.copytree(repo, dest, ignore=shutil.ignore_patterns(".git"))
    return dest


def test_blob_hash_is_gits(checkout: Path) -> None:
    data = (checkout / "plls_bench/a.py").read_bytes()
    assert blob_hash(data) == _git(checkout, "hash-object", "plls_bench/a.py").strip()


def test_an_exact_copy_passes_and_names_the_commit(checkout: Path, tmp_path: Path, capsys) -> None:
    manifest = tmp_path / "MANIFEST"
    manifest.write_text(write_manifest(checkout))
    commit, blobs = read_manifest(manifest.read_text())
    assert commit == _git(checkout, "rev-parse", "HEAD").strip()
    assert sorted(blobs) == ["conf/config.yaml", "plls_bench/a.py", "plls_bench/sub/b.py"]  # docs/ is not code
    copy = _copy(checkout, tmp_path / "copy")
    (copy / "plls_bench/__pycache__").mkdir()
    (copy / "plls_bench/__pycache__/a.cpython-312.pyc").write_bytes(b"\0")  # build output is not code
    assert main(["check", str(manifest), "--root", str(copy)]) == 0
    assert capsys.readouterr().out.strip() == commit


def test_a_changed_missing_or_extra_file_fails(checkout: Path, tmp_path: Path, capsys) -> None:
    manifest = tmp_path / "MANIFEST"
    manifest.write_text(write_manifest(checkout))
    copy = _copy(checkout, tmp_path / "copy")
    (copy / "plls_bench/a.py").write_text("A = 3\n")
    (copy / "plls_bench/sub/b.py").unlink()
    (copy / "conf/extra.yaml").write_text("x: 1\n")
    _, blobs = read_manifest(manifest.read_text())
    assert check_copy(blobs, copy) == ["differs: plls_bench/a.py", "missing: plls_bench/sub/b.py",
                                       "not in the manifest: conf/extra.yaml"]
    assert main(["check", str(manifest), "--root", str(copy)]) == 1
    captured = capsys.readouterr()
    assert captured.out == ""  # nothing to export as the commit
    assert "3 problem(s) in 3 files" in captured.err


def test_write_refuses_uncommitted_code(checkout: Path) -> None:
    (checkout / "conf/config.yaml").write_text("seed: 1\n")
    with pytest.raises(ManifestError, match="uncommitted changes to the code: M conf/config.yaml"):
        write_manifest(checkout)


def test_bad_manifest_is_one_clear_error(tmp_path: Path) -> None:
    bad = tmp_path / "MANIFEST"
    bad.write_text("not a manifest\n")
    result = subprocess.run([sys.executable, "-m", "plls_bench.rundirs.manifest", "check", str(bad)],
                            capture_output=True, text=True)
    assert result.returncode == 2
    assert result.stderr.strip() == "plls_bench.rundirs.manifest: not a manifest: its first line must be 'commit <sha>'"
    missing = main(["check", str(tmp_path / "nowhere")])
    assert missing == 2
