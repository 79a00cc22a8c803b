"""mkdocs hooks (mkdocs.yml, ``hooks:``): the site is built from ``docs/`` and the files of the
repository that its pages link, so ``results/`` (the claims table, the figures) and ``conf/`` files
are served as they are committed, never copied into ``docs/``.

A page links a repository file as GitHub shows it, relative to ``docs/`` (``../results/README.md``,
``../conf/algo/ppo.yaml``). Such a file is published at its repository path (``results/README.md``),
markdown files it links in turn too, and the page's link is pointed there. A link to a file that
does not exist is left alone, so the strict build fails on it. Anchors follow GitHub's rule, so a
``#heading`` link means the same on GitHub and on the site.
"""
from __future__ import annotations

import posixpath
import re
from pathlib import Path
from typing import Any

from mkdocs.structure.files import File, Files, InclusionLevel

REPO = Path(__file__).resolve().parent
LINK = re.compile(r"(!?\[[^\]]*\]\()([^)\s#]+)(#[^)\s]*)?\)")
EXTERNAL = re.compile(r"^[a-z][a-z0-9+.-]*:", re.IGNORECASE)  # http:, mailto:, ...


def github_slug(value: str, separator: str = "-") -> str:
    """GitHub's heading anchor: lower case, punctuation dropped, each space a hyphen (not merged)."""
    return re.sub(r"[^\w\- ]", "", value.strip().lower()).replace(" ", separator)


def on_config(config: Any) -> Any:
    config.mdx_configs.setdefault("toc", {})["slugify"] = github_slug
    return config


def _linked(text: str, source: str) -> set[str]:
    """Repository paths of the local files ``text`` links (``source``: its repository path)."""
    found = set()
    for _, target, _ in LINK.findall(text):
        if not EXTERNAL.match(target) and not target.startswith("/"):
            found.add(posixpath.normpath(posixpath.join(posixpath.dirname(source), target)))
    return found


def on_files(files: Files, config: Any) -> Files:
    docs = Path(config.docs_dir).resolve().relative_to(REPO).as_posix()
    queue = [f"{docs}/{page.src_uri}" for page in files.documentation_pages()]
    queue += [item for item in _nav_paths(config.nav) if not item.startswith(f"{docs}/")]
    seen = set(queue)
    while queue:
        source = queue.pop()
        path = REPO / source
        if source.endswith(".md") and path.is_file():
            for target in _linked(path.read_text(), source) - seen:
                seen.add(target)
                queue.append(target)
        if not source.startswith(f"{docs}/") and path.is_file() and files.get_file_from_path(source) is None:
            inclusion = InclusionLevel.NOT_IN_NAV if source not in _nav_paths(config.nav) else InclusionLevel.UNDEFINED
            files.append(File.generated(config, source, abs_src_path=str(path), inclusion=inclusion))
    return files


def _nav_paths(nav: Any) -> list[str]:
    """The page paths of the nav (mkdocs.yml), nested sections included."""
    if isinstance(nav, str):
        return [nav]
    if isinstance(nav, dict):
        return [p for value in nav.values() for p in _nav_paths(value)]
    if isinstance(nav, list):
        return [p for item in nav for p in _nav_paths(item)]
    return []


def on_page_markdown(markdown: str, page: Any, config: Any, files: Files) -> str:
    """Point a docs page's links out of ``docs/`` at the published copy of the file."""
    docs = Path(config.docs_dir).resolve().relative_to(REPO).as_posix()
    if not Path(page.file.abs_src_path).resolve().is_relative_to(REPO / docs):
        return markdown  # a published repository file: its links are relative to where it lives
    here = posixpath.dirname(f"{docs}/{page.file.src_uri}")

    def repoint(match: re.Match[str]) -> str:
        opening, target, anchor = match.group(1), match.group(2), match.group(3) or ""
        if EXTERNAL.match(target) or target.startswith("/"):
            return match.group(0)
        resolved = posixpath.normpath(posixpath.join(here, target))
        if resolved.startswith(f"{docs}/") or files.get_file_from_path(resolved) is None:
            return match.group(0)
        return f"{opening}{posixpath.relpath(resolved, posixpath.dirname(page.file.src_uri) or '.')}{anchor})"

    return LINK.sub(repoint, markdown)
