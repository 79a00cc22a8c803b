"""The README's headline results and profile table are the collector's: the committed headline is
what the committed results/ give, every claim it names is in the claims table, the profile table is
the dry run's plan of a fresh clone, and the collector rewrites both blocks only in this checkout's
README, between their markers."""
from __future__ import annotations

import csv
from pathlib import Path

import pytest

from plls_bench.pipeline.plan_totals import plan_totals
from plls_bench.report import headline, profile_costs
from plls_bench.report.headline import END, HEADLINE_CLAIMS, START, build_headline, with_block, with_headline
from tests.conftest import REPO_ROOT


def test_the_committed_headline_is_what_the_committed_results_give() -> None:
    page = (REPO_ROOT / "README.md").read_text()
    block = build_headline(REPO_ROOT / "results")
    assert with_headline(page, block) == page, (
        "README.md's headline is stale: regenerate results/ with "
        "`python -m plls_bench.report --records-only`, which rewrites it")
    assert page.index(START) < 40 * 80, "the headline sits near the top of the front page"


def test_every_headline_claim_is_a_claim_of_the_paper_table() -> None:
    with open(REPO_ROOT / "results" / "paper" / "claims.csv", newline="") as handle:
        claims = {row["claim"] for row in csv.DictReader(handle)}
    missing = [claim for _, claim in HEADLINE_CLAIMS if claim not in claims]
    assert not missing, ("plls_bench/report/headline.py names claims results/paper/claims.csv lacks:\n"
                         + "\n".join(missing))
    figure = REPO_ROOT / headline.FIGURE[1]
    assert figure.is_file(), f"the headline figure {figure} is not in results/"


def test_the_block_counts_verdicts_and_tables_the_named_claims(tmp_path: Path) -> None:
    (tmp_path / "tables").mkdir()
    named = HEADLINE_CLAIMS[0][1]
    tested = HEADLINE_CLAIMS[1][1]
    fields = {"test": "", "statistic": "", "p": "", "p_adjusted": ""}
    rows = [{"claim": named, "paper": "P | x", "suite": "0.5 [0, 1]; a reading", "verdict": "inconclusive", **fields},
            {"claim": tested, "paper": "1", "suite": "3 vs 2", "verdict": "reproduced",
             "test": "Welch t", "statistic": "3.14159", "p": "0.004", "p_adjusted": "0.012"},
            {"claim": "a third", "paper": "1", "suite": "2", "verdict": "reproduced", **fields}]
    with open(tmp_path / "tables" / "claims.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    block = build_headline(tmp_path)
    assert block.startswith(START) and block.endswith(END)
    assert "**3 claims judged**" in block and "2 reproduced, 1 inconclusive" in block
    assert f"| {HEADLINE_CLAIMS[0][0]} | {named} | P \\| x | 0.5 [0, 1] | — | inconclusive |" in block
    assert f"| {tested} | 1 | 3 vs 2 | Welch t = 3.14, p = 0.004, Holm-adjusted p = 0.012 | reproduced |" in block, \
        "the test's own p, then the adjusted p the verdict reads"
    assert block.count("not in the claims table") == len(HEADLINE_CLAIMS) - 2
    page = f"# T\n\nintro\n{START}\nold\n{END}\nrest\n"
    assert with_headline(page, block) == f"# T\n\nintro\n{block}\nrest\n"
    with pytest.raises(ValueError, match="no `<!-- headline"):
        with_headline("# no markers\n", block)


def test_only_this_checkouts_results_rewrite_the_readme(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    front = tmp_path / "README.md"
    monkeypatch.setattr(headline, "FRONT_PAGE", front)
    monkeypatch.setattr(headline, "RESULTS", (REPO_ROOT / "results").resolve())
    front.write_text(f"# T\n{START}\nold\n{END}\n")
    assert not headline.write_front_page(tmp_path / "results")  # a smoke or test output folder
    assert "old" in front.read_text()
    assert headline.write_front_page(REPO_ROOT / "results")
    assert front.read_text() == f"# T\n{build_headline(REPO_ROOT / 'results')}\n"
    profiles = f"{profile_costs.START}\nplanned\n{profile_costs.END}"
    monkeypatch.setattr(headline, "build_profiles", lambda: profiles)
    front.write_text(f"# T\n{START}\nold\n{END}\n{profile_costs.START}\nold\n{profile_costs.END}\n")
    assert headline.write_front_page(REPO_ROOT / "results")
    assert front.read_text() == f"# T\n{build_headline(REPO_ROOT / 'results')}\n{profiles}\n"
    front.write_text("# T without markers\n")
    assert not headline.write_front_page(REPO_ROOT / "results") and front.read_text() == "# T without markers\n"


def test_the_committed_profile_table_is_what_the_plan_gives() -> None:
    """The README's profile costs are the dry run's on a fresh clone, from committed inputs only."""
    page = (REPO_ROOT / "README.md").read_text()
    block = profile_costs.build_profiles()
    assert with_block(page, block, profile_costs.START, profile_costs.END) == page, (
        "README.md's profile table is stale: rerun the collector (`python -m plls_bench.report "
        "--records-only`), which rewrites it")
    quick = profile_costs.plan_profile("quick", str(profile_costs.FRESH_RUNS))
    totals = plan_totals(quick)
    assert f"{totals.seconds / 3600:,.1f} left on a fresh clone ({totals.pending} of {totals.trials} trials" in block
    assert not profile_costs.FRESH_RUNS.exists(), "planning a fresh clone made its runs dir"


def test_the_profile_table_reads_the_measured_smoke_time_and_plans_no_local_runs(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    bench = tmp_path / "benchmarks.md"
    begin, end = profile_costs.SMOKE_SECTION
    section = ("Machine: vm: x86_64, 2 cores, load average 1.0  \nMeasured: 2026-11-21  \n"
               "**finished in 157 s (2.6 min)**: ...\n\n| preset | outcome | seconds |\n|---|---|---|\n"
               "| `a_data` | ok | 3 |\n| `b_ppo` | ok | 9 |\n")
    bench.write_text(f"# B\n{begin}\n{section}{end}\n")
    assert profile_costs.smoke_timing(bench) == (2.6, "2026-11-21", "2", 2)
    bench.write_text(f"# B\n{begin}\n{section.replace('Measured: 2026-11-21  ', '')}{end}\n")
    with pytest.raises(ValueError, match="Measured:"):
        profile_costs.smoke_timing(bench)
    monkeypatch.setattr(profile_costs, "FRESH_RUNS", tmp_path)  # a runs dir with trials of this machine
    with pytest.raises(ValueError, match="exists"):
        profile_costs.build_profiles()
