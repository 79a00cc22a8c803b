"""The front page's headline results: claim counts, one short table of paper vs suite vs verdict per
task, one figure. Built from the claims table the collector has just written and put into the
repository's ``README.md`` between two markers, so the front page cannot go stale:
``tests/test_front_page.py`` fails when the committed block differs from what ``results/`` gives."""
from __future__ import annotations

import csv
from collections import Counter
from pathlib import Path

from plls_bench.core.atomic_files import atomic_write_bytes
from plls_bench.report.evidence.verdicts import INCONCLUSIVE, INTERIM, NOT_REPRODUCED, REPRODUCED
from plls_bench.report.profile_costs import END as PROFILES_END
from plls_bench.report.profile_costs import START as PROFILES_START
from plls_bench.report.profile_costs import build_profiles

REPO = Path(__file__).resolve().parents[2]
FRONT_PAGE = REPO / "README.md"
RESULTS = REPO / "results"  # only a collector writing here updates the front page
START = "<!-- headline: written by `python -m plls_bench.report`; edit plls_bench/report/headline.py, not this -->"
END = "<!-- /headline -->"
# The claims the front page shows, per task: the paper's main comparison on each, and the readings
# that decide it (exploration on MountainCar, sampled actions on CarRacing, the DBC baseline check).
HEADLINE_CLAIMS = (
    ("MountainCar", "PL-LS with PPO beats PPO on MountainCar (final return) [Gaussian exploration, literal]"),
    ("MountainCar", "PL-LS with PPO beats PPO on MountainCar (final return) [gSDE exploration]"),
    ("CarRacing", "PL-LS with PPO beats PPO on CarRacing (final return)"),
    ("CarRacing", "PL-LS with PPO beats PPO on CarRacing (final return; sampled actions)"),
    ("CarRacing", "PL-LS (V_s + V_a) beats PPO + V_s only (final return)"),
    ("cheetah-run", "PL-LS with DBC obtains higher returns than DBC (final return)"),
    ("cheetah-run", "Suite DBC reaches the published pixel range on cheetah-run at 100k env steps (final return)"),
)
FIGURE = ("Fig. 18: CarRacing, PL-LS + PPO against PPO", "results/figures/fig18.png")
VERDICT_ORDER = (REPRODUCED, NOT_REPRODUCED, INCONCLUSIVE, INTERIM)  # others follow in the table's order


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ") or "—"


def _first_clause(suite: str) -> str:
    """The suite's value without the readings the full table adds after it (its first clause)."""
    return suite.split("; ")[0]


def _test_text(row: dict[str, str]) -> str:
    """The decision's test, statistic and p, with the Holm-adjusted p the verdict reads where the
    row is one of a family (a bare adjusted p would read as the test's own)."""
    if row.get("test") in ("", "none", None) or not row.get("p"):
        return ""
    text = f"{row['test']} = {float(row['statistic']):.3g}, p = {float(row['p']):.2g}"
    if row.get("p_adjusted"):
        text += f", Holm-adjusted p = {float(row['p_adjusted']):.2g}"
    return text


def build_headline(results_dir: Path) -> str:
    """The block between the markers (markers included) from ``results_dir/tables/claims.csv``."""
    with open(Path(results_dir) / "tables" / "claims.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    counts = Counter(row["verdict"] for row in rows)
    order = [v for v in VERDICT_ORDER if v in counts] + [v for v in counts if v not in VERDICT_ORDER]
    by_claim = {row["claim"]: row for row in rows}
    lines = [START, "",
             f"**{len(rows)} claims judged** (every quantitative claim of the paper, and the baseline checks): "
             + ", ".join(f"{counts[v]} {v}" for v in order) + ". Full table: "
             "[results/tables/claims.md](results/tables/claims.md); every table and figure: "
             "[results/README.md](results/README.md).", "",
             "| Task | Claim | Paper | Suite | Test | Verdict |", "|---|---|---|---|---|---|"]
    for task, claim in HEADLINE_CLAIMS:
        row = by_claim.get(claim)
        if row is None:
            lines.append(f"| {task} | {_cell(claim)} | — | — | — | not in the claims table |")
        else:
            lines.append(f"| {task} | {_cell(claim)} | {_cell(row['paper'])} | {_cell(_first_clause(row['suite']))} "
                         f"| {_cell(_test_text(row))} | {_cell(row['verdict'])} |")
    title, path = FIGURE
    lines += ["", f"![{title}]({path})", "", END]
    return "\n".join(lines)


def with_headline(page: str, block: str) -> str:
    """``page`` with the text between its headline markers replaced by ``block``; ValueError without them."""
    return with_block(page, block, START, END)


def with_block(page: str, block: str, start_marker: str, end_marker: str) -> str:
    """``page`` with the text from ``start_marker`` to ``end_marker`` replaced by ``block`` (which
    holds both markers); ValueError without them."""
    start, end = page.find(start_marker), page.find(end_marker)
    if start < 0 or end < start:
        raise ValueError(f"the front page has no `{start_marker}` ... `{end_marker}` block")
    return page[:start] + block + page[end + len(end_marker):]


def write_front_page(out_dir: Path) -> bool:
    """Rewrite the README's headline (and its profile table, :mod:`profile_costs`) when ``out_dir`` is
    this checkout's ``results/`` (not a smoke or test output folder) and the README holds the
    markers; True when it was written."""
    if Path(out_dir).resolve() != RESULTS or not FRONT_PAGE.is_file():
        return False
    page = FRONT_PAGE.read_text()
    if START not in page:
        return False
    updated = with_headline(page, build_headline(RESULTS))
    if PROFILES_START in updated:  # the profile table, planned from the committed inputs alone
        updated = with_block(updated, build_profiles(), PROFILES_START, PROFILES_END)
    if updated != page:
        atomic_write_bytes(FRONT_PAGE, updated.encode())
    return True
