"""``results/README.md``: the generated index. It names the budget profile(s) the runs used,
the commits that produced them, the newest evidence and the commit of the collector's code, then
shows the paper vs suite table, every table and every figure inline, and every gap. Nothing in it
depends on when or in which checkout it was generated, so the same records give the same file."""
from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

from plls_bench.config import BUDGET_NAMES
from plls_bench.core.atomic_files import atomic_write_bytes, read_json
from plls_bench.report.evidence.entry_types import IdStatus
from plls_bench.report.evidence.table_formats import plural
from plls_bench.rundirs.provenance import git_state
from plls_bench.rundirs.run_dir import iter_run_dirs

BUDGET_ORDER = BUDGET_NAMES  # ordered from the smallest profile up
# What the collector's output depends on: its code (and the modules it reads runs with) and the
# paper's numbers; their last commit names the collector in every checkout that left them alone.
COLLECTOR_PATHS = ("plls_bench", "results/paper")
STATUSES = ("ok", "partial", "empty", "error")  # partial = drawn, with gaps; empty = nothing to draw


def _runs_summary(runs_dir: Path | None, records_dir: Path | None = None) -> list[str]:
    """Budget profiles and producing commits of every run dir and committed record (read-only)."""
    budgets: Counter[str] = Counter()
    commits: Counter[str] = Counter()
    updated: list[str] = []  # status.json times (ISO 8601, UTC): the newest is the evidence's date
    roots = [root for root in (runs_dir, records_dir) if root is not None]
    seen: set[Path] = set()  # a run and its record are one run
    for root, path in ((r, p) for r in roots for p in iter_run_dirs(r)):
        if path.relative_to(root) in seen:
            continue
        seen.add(path.relative_to(root))
        config = (read_json(path / "config.json") or {}).get("config", {})
        budgets[(config.get("budget") or {}).get("name", "unknown")] += 1
        provenance = read_json(path / "provenance.json") or {}
        sha = provenance.get("git_sha") or "unknown"
        commits[f"{sha[:10]}{' (dirty)' if provenance.get('git_dirty') else ''}"] += 1
        updated.append(str((read_json(path / "status.json") or {}).get("updated") or ""))
    if not budgets:
        return [f"- Runs: none found under `{'` or `'.join(map(str, roots))}`."]
    largest = max(budgets, key=lambda b: BUDGET_ORDER.index(b) if b in BUDGET_ORDER else -1)
    return [f"- Budget profile: **{largest}** (largest found); run dirs per profile: "
            + ", ".join(f"{b} {n}" for b, n in sorted(budgets.items())),
            "- Runs produced at commit(s): "
            + ", ".join(f"`{c}` ({plural(n, 'run')})" for c, n in commits.most_common()),
            f"- Newest evidence: {max(updated) or 'unknown'} (the latest status update of a run read)"]


def _files(status: IdStatus, *exts: str) -> str:
    links = [f"[{Path(f).suffix[1:].upper()}]({f})" for f in status.files if Path(f).suffix[1:] in exts]
    return " · ".join(links)


def _gaps(status: IdStatus) -> list[str]:
    lines = [f"- gap: {g}" for g in status.gaps]
    return lines + ([f"- **error**: {status.error}"] if status.error else [])


def _header(status: IdStatus) -> list[str]:
    trials = ", ".join(f"{k}: {v}" for k, v in status.trials.items()) or "none"
    return [f"### {status.ref}: {status.title}", "",
            f"Status **{status.status}** · shown: {trials} · from `{'`, `'.join(status.experiments)}` "
            f"(variant `default`), reading {status.reads}", ""]


def _table_section(out_dir: Path, status: IdStatus) -> list[str]:
    md = out_dir / "tables" / f"{status.id}.md"
    body = md.read_text().strip() if status.status != "error" and md.is_file() else "*not rendered*"
    return [*_header(status), body, "", f"Files: {_files(status, 'md', 'tex', 'csv')}", "", *_gaps(status), ""]


def _variants_section(out_dir: Path, status: IdStatus) -> list[str]:
    """One index line per variant found, its table, then each preset's figure of its variants."""
    found = [f"- {line}" for line in status.lines] or ["No variant found: every run dir is a preset's default."]
    lines = ["Every `<preset>/<variant>` run dir found beside the preset's default runs: an ablation override "
             "(`reproduce --override KEY=VALUE`, docs/ablations.md) or a declared sweep's value.", "",
             f"Status **{status.status}** · reading {status.reads}", "", *found, ""]
    md = out_dir / "tables" / f"{status.id}.md"
    lines += [md.read_text().strip() if status.status != "error" and md.is_file() else "*not rendered*", "",
              "Files: " + " · ".join(f"[{Path(f).suffix[1:].upper()}]({f})" for f in status.files
                                     if f.startswith("tables/")), ""]
    for png in (f for f in status.files if f.endswith(".png")):
        stem = Path(png).with_suffix("")
        lines += [f"![{stem.name}]({png})", "",
                  "Files: " + " · ".join(f"[{ext.upper()}]({stem}.{ext})" for ext in ("png", "pdf", "csv")), ""]
    gaps = _gaps(status)
    return lines + gaps + ([""] if gaps else [])


def _figure_section(status: IdStatus) -> list[str]:
    png = next((f for f in status.files if f.endswith(".png")), None)
    image = f"![{status.ref}]({png})" if png else "*not rendered*"
    return [*_header(status), image, "", f"Files: {_files(status, 'png', 'pdf', 'csv')}", "", *_gaps(status), ""]


def build_readme(out_dir: Path, runs_dir: Path | None, index: list[IdStatus], meta: dict[str, Any]) -> str:
    git = git_state(paths=COLLECTOR_PATHS)
    counts = Counter(s.status for s in index)
    lines = ["# Results", "",
             "Generated by `python -m plls_bench.report` — do not edit by hand; rerun it instead.", "",
             f"- Collector: `{git['git_sha'] or 'unknown'}`, the last commit to change "
             + " or ".join(f"`{p}/`" for p in COLLECTOR_PATHS)
             + (" (they have uncommitted changes)" if git["git_dirty"] else ""),
             f"- Runs dir: {'not read (`--records-only`)' if runs_dir is None else f'`{runs_dir}`'}; "
             f"committed records: `{meta.get('records') or 'not read'}`; "
             f"curves drawn against `{meta['x_axis']}`",
             *_runs_summary(runs_dir, Path(meta["records"]) if meta.get("records") else None),
             f"- Ids: {len(index)}: " + ", ".join(f"{counts.get(s, 0)} {s}" for s in STATUSES)
             + " (partial = drawn with gaps listed below it; empty = no runs to draw from)", ""]
    claims = next((s for s in index if s.id == "claims"), None)
    if claims is not None:
        lines += ["## Paper vs suite", "", *_table_section(out_dir, claims)[2:]]
    variants = next((s for s in index if s.id == "variants"), None)
    if variants is not None:
        lines += ["## Variants", "", *_variants_section(out_dir, variants)]
    lines += ["## Tables", ""]
    for status in index:
        if status.kind == "table" and status.id not in ("claims", "variants"):
            lines += _table_section(out_dir, status)
    lines += ["## Figures", ""]
    for status in index:
        if status.kind == "figure":
            lines += _figure_section(status)
    all_gaps = list(dict.fromkeys(g for s in index for g in s.gaps))
    lines += ["## Every gap", "", *(f"- {g}" for g in all_gaps), "" if all_gaps else "None.", ""]
    return "\n".join(lines)


def write_readme(out_dir: Path, runs_dir: Path | None, index: list[IdStatus], meta: dict[str, Any]) -> None:
    atomic_write_bytes(out_dir / "README.md", build_readme(out_dir, runs_dir, index, meta).encode())
