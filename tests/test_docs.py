"""Every reference in the tracked text resolves inside the repository: no document a clone lacks,
no file path that does not exist, no decision id that docs/decisions.md does not define, no link of
the README or a docs page to a missing file or heading. docs/ holds prose only, every page of it in
the site's nav (mkdocs.yml), and the README stays a front page."""
from __future__ import annotations

import fnmatch
import itertools
import re
import subprocess
from pathlib import Path

from tests.conftest import REPO_ROOT

TEXT_SUFFIXES = (".py", ".yaml", ".md", ".sh", ".toml", ".csv")  # csv: the claims rows in results/paper
EXCLUDED_DIRS = ("results/records/",)  # committed run records: data, not prose
# Internal working documents the users of the repository never had (split so this file does not
# match itself).
FOREIGN_DOCS = ("PAPER" + "_SPEC", "DESIGN" + ".md")
# Directories whose files comments name; a token under them must be a tracked file.
PATH_ROOTS = ("bench", "plls_bench", "baselines", "conf", "docs", "tests", "results/analysis",
              "results/paper", "results/tables", "results/figures", "results/resolved", "results/gpu_runs")
PATH_TOKEN = re.compile(
    r"(?<![\w./-])((?:" + "|".join(re.escape(r) for r in PATH_ROOTS) + r")/[\w./<>{},*-]*?"
    r"\.(?:py|yaml|md|json|csv|sh|toml|tex|png|pdf))(?![\w])")
# Hydra group paths written relative to conf/ in conf/ comments and in the docs (the Configuration
# page: e.g. `algo/per_env/ppo_mountaincar.yaml`).
CONF_GROUPS = ("algo", "budget", "env", "experiment", "filmstrip", "hydra", "repr", "study")
CONF_TOKEN = re.compile(r"(?<![\w./-])((?:" + "|".join(CONF_GROUPS) + r")/[\w./<>{},*-]*?\.yaml)(?![\w])")
# Paths a run creates, which no clone holds.
CREATED_BY_RUNS = ("results/runs/",)
# Tests whose fixtures build a tree of their own, so they name files this one lacks.
FIXTURE_FILES = ("tests/test_docs.py", "tests/test_manifest.py")
# docs/architecture.md's "Adding a runner" walks through files a reader creates for a SAC baseline.
EXAMPLE_PAGE = "docs/architecture.md"
EXAMPLE_NEW_FILES = ("plls_bench/train/sac.py", "conf/algo/sac.yaml", "conf/experiment/cheetah_sac.yaml")
DECISION_CITE = re.compile(r"decisions(?:\.md)?(?:#d|,? D)(\d+)\b", re.IGNORECASE)
DECISION_HEADING = re.compile(r'^<a id="d(\d+)"></a>\n### D(\d+): \S', re.MULTILINE)
DECISIONS = REPO_ROOT / "docs" / "decisions.md"


def tracked_text_files() -> list[str]:
    """The prose and code of the repository as git tracks it (not the run records)."""
    out = subprocess.run(["git", "ls-files"], cwd=REPO_ROOT, capture_output=True, text=True, check=True)
    return [f for f in out.stdout.splitlines()
            if f.endswith(TEXT_SUFFIXES) and not f.startswith(EXCLUDED_DIRS) and (REPO_ROOT / f).is_file()]


def expand(token: str) -> list[str]:
    """``a/{x,y}.py`` -> both spellings; ``<env>``, ``{name}`` and ``*`` become glob wildcards."""
    parts = re.split(r"(\{[^{}]*,[^{}]*\})", token)
    options = [p[1:-1].split(",") if p.startswith("{") and "," in p else [p] for p in parts]
    spelled = ["".join(choice) for choice in itertools.product(*options)]
    return [re.sub(r"<[^<>]*>|\{[^{},]*\}", "*", s) for s in spelled]


def exists(pattern: str, tracked: set[str]) -> bool:
    """A literal path that is tracked (or a tracked directory's file), or a glob matching one."""
    if "*" in pattern:
        return any(fnmatch.fnmatch(f, pattern) for f in tracked)
    return pattern in tracked or (REPO_ROOT / pattern).is_file()


def missing_paths(name: str, text: str, tracked: set[str]) -> list[str]:
    """Path tokens in ``text`` that name no file of the tree."""
    found = [(t, "") for t in PATH_TOKEN.findall(text)]
    if name.startswith(("conf/", "docs/")) or name == "README.md":
        found += [(t, "conf/") for t in CONF_TOKEN.findall(text)]
    bad = []
    for token, root in found:
        if token.startswith(CREATED_BY_RUNS) or (name == EXAMPLE_PAGE and token in EXAMPLE_NEW_FILES):
            continue
        if not all(exists(root + p, tracked) for p in expand(token)):
            bad.append(f"{name}: {root}{token}")
    return bad


def test_the_path_check_finds_a_missing_file_and_accepts_placeholders() -> None:
    tracked = {"bench/env_speed.py", "conf/env/backend/carracing_quick.yaml",
               "conf/env/backend/carracing_paper.yaml", "conf/algo/per_env/ppo_mountaincar.yaml"}
    text = ("# about 10x (`bench/envpool_speed.py`, bench/env_speed.py); conf/env/backend/carracing_"
            "{quick,paper}.yaml, `algo/per_env/ppo_<env>.yaml`, conf/budget/per_env/<env>_<profile>.yaml, "
            "results/runs/<experiment>/x.json")
    assert missing_paths("conf/x.yaml", text, tracked) == [
        "conf/x.yaml: bench/envpool_speed.py", "conf/x.yaml: conf/budget/per_env/<env>_<profile>.yaml"]


def test_no_reference_to_documents_outside_the_repository() -> None:
    hits = [f"{name}:{number}: {line.strip()}"
            for name in tracked_text_files()
            for number, line in enumerate((REPO_ROOT / name).read_text(errors="replace").splitlines(), 1)
            if any(doc in line for doc in FOREIGN_DOCS)]
    assert not hits, ("cite docs/decisions.md, a README section or the paper instead of "
                      "internal documents:\n" + "\n".join(hits))


def test_every_named_repo_file_exists() -> None:
    files = [f for f in tracked_text_files() if f not in FIXTURE_FILES]
    tracked = set(subprocess.run(["git", "ls-files"], cwd=REPO_ROOT, capture_output=True, text=True,
                                 check=True).stdout.splitlines())
    bad = [hit for name in files for hit in missing_paths(name, (REPO_ROOT / name).read_text(errors="replace"),
                                                          tracked)]
    assert not bad, "comments or docs name files that do not exist:\n" + "\n".join(sorted(set(bad)))


def test_decision_record_ids_are_numbered_and_anchored() -> None:
    text = DECISIONS.read_text()
    pairs = DECISION_HEADING.findall(text)
    assert pairs, "docs/decisions.md has no `<a id=\"dN\"></a>` + `### DN: ...` headings"
    assert all(a == b for a, b in pairs), f"anchor and heading numbers differ: {pairs}"
    numbers = [int(a) for a, _ in pairs]
    assert numbers == list(range(1, len(numbers) + 1)), f"decision ids not 1..n in order: {numbers}"
    contents = text.split("\n## ", 2)[1] if "\n## " in text else ""
    for n in numbers:
        assert f"(#d{n})" in contents, f"D{n} is missing from the table of contents"


def test_every_cited_decision_exists() -> None:
    defined = {int(a) for a, _ in DECISION_HEADING.findall(DECISIONS.read_text())}
    cited = []
    for name in tracked_text_files():
        text = (REPO_ROOT / name).read_text(errors="replace")
        cited += [(name, int(n)) for n in DECISION_CITE.findall(text)]
        if name == "docs/decisions.md":
            cited += [(name, int(n)) for n in re.findall(r"\(#d(\d+)\)", text)]
    assert cited, "nothing cites the decision record"
    unknown = sorted({f"{name}: D{n}" for name, n in cited if n not in defined})
    assert not unknown, "citations of decisions docs/decisions.md does not define:\n" + "\n".join(unknown)


def github_anchor(heading: str) -> str:
    """GitHub's anchor of a markdown heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = path.read_text()
    return ({github_anchor(h) for h in re.findall(r"^#+ (.+)$", text, re.MULTILINE)}
            | set(re.findall(r'<a id="([^"]+)"></a>', text)))


def test_decision_record_links_resolve() -> None:
    """Every relative link of the decision record names a file of the tree and, for markdown, one
    of its headings."""
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", DECISIONS.read_text()):
        file, _, anchor = target.partition("#")
        path = (DECISIONS.parent / file).resolve() if file else DECISIONS
        if not path.is_file():
            broken.append(f"{target}: no such file")
        elif anchor and path.suffix == ".md" and anchor not in anchors(path):
            broken.append(f"{target}: no heading #{anchor} in {path.relative_to(REPO_ROOT)}")
    assert not broken, "docs/decisions.md links that do not resolve:\n" + "\n".join(broken)


def broken_links(page: Path) -> list[str]:
    """Relative links of a markdown page that name no file of the tree or, for markdown, none of its
    headings (GitHub's anchors, which the docs site uses too: mkdocs_hooks.py)."""
    broken = []
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.DOTALL)  # code blocks hold no links
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.IGNORECASE):
            continue  # http:, mailto:
        file, _, anchor = target.partition("#")
        path = (page.parent / file).resolve() if file else page
        if not path.is_file():
            broken.append(f"{page.relative_to(REPO_ROOT)}: {target}: no such file")
        elif anchor and path.suffix == ".md" and anchor not in anchors(path):
            broken.append(f"{page.relative_to(REPO_ROOT)}: {target}: no heading #{anchor} in "
                          f"{path.relative_to(REPO_ROOT)}")
    return broken


def test_every_link_of_the_readme_and_the_docs_resolves() -> None:
    pages = [REPO_ROOT / "README.md", *sorted((REPO_ROOT / "docs").glob("*.md"))]
    broken = [hit for page in pages for hit in broken_links(page)]
    assert not broken, "links that do not resolve:\n" + "\n".join(broken)


def test_the_link_check_finds_a_missing_file_and_a_missing_heading(tmp_path: Path) -> None:
    page = REPO_ROOT / "docs" / "index.md"  # a real page's folder, so relative paths resolve as there
    probe = page.with_name(f".{tmp_path.name}.md")
    probe.write_text("# Probe\n\n[a](status.md) [b](nope.md) [c](status.md#no-such-heading) [d](#probe)\n")
    try:
        found = broken_links(probe)
    finally:
        probe.unlink()
    assert [hit.split(": ", 1)[1] for hit in found] == ["nope.md: no such file",
                                                         "status.md#no-such-heading: no heading #no-such-heading "
                                                         "in docs/status.md"]


def mkdocs_nav() -> list[str]:
    """The page paths of mkdocs.yml's nav (read as text: the file has no tags to resolve)."""
    text = (REPO_ROOT / "mkdocs.yml").read_text()
    return re.findall(r"^\s*- [^:\n]+: (\S+\.md)\s*$", text.split("\nnav:", 1)[1], re.MULTILINE)


def test_docs_hold_prose_and_every_page_is_in_the_site() -> None:
    listed = ["git", "ls-files", "--cached", "--others", "--exclude-standard", "docs"]  # new pages too
    tracked = subprocess.run(listed, cwd=REPO_ROOT, capture_output=True, text=True, check=True).stdout.split()
    generated = [name for name in tracked if not name.endswith(".md")]
    assert not generated, "docs/ holds prose; generated files belong beside the results:\n" + "\n".join(generated)
    nav = mkdocs_nav()
    pages = sorted(name.removeprefix("docs/") for name in tracked)
    assert sorted(p for p in nav if not p.startswith("results/")) == pages, "mkdocs.yml nav vs docs/*.md"
    assert all((REPO_ROOT / p).is_file() for p in nav if p.startswith("results/")), "a results/ page is missing"


def test_the_readme_is_a_front_page() -> None:
    lines = (REPO_ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 250, f"README.md has {len(lines)} lines; details belong in a docs/ page"
    linked = set(re.findall(r"\]\(docs/([\w-]+\.md)\)", "\n".join(lines)))
    assert linked == {p for p in mkdocs_nav() if "/" not in p} - {"index.md"}, "the README indexes every docs page"
