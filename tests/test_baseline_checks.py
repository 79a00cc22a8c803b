"""Baseline checks chain: a comparison reads its check's verdict after that check's own gate, and a
chain of ``requires`` that leads back to a row on it is refused, naming the line."""
from __future__ import annotations

import csv
from pathlib import Path

import pytest

from plls_bench.report.claims.claims_table import read_claims
from plls_bench.report.collect import PAPER_DIR
from plls_bench.report.evidence.verdicts import (
    INCONCLUSIVE,
    NOT_MADE,
    NOT_REPRODUCED,
    REPRODUCED,
    Estimate,
    Judged,
    gate_all,
)

DBC_CHECK = "Suite DBC reaches the published pixel range on cheetah-run at 100k env steps (final return)"


def chain(verdicts: dict[str, str]) -> tuple[list[dict[str, str]], dict[str, Judged]]:
    """Claims ``method`` -> ``baseline`` -> ``sac`` (each requires the next), judged as ``verdicts``."""
    requires = {"method": "baseline", "baseline": "sac", "sac": ""}
    claims = [{"claim": name, "requires": required} for name, required in requires.items()]
    judged = {name: (Estimate(1.0, (0.5, 1.5), f"{name} 1.0", "quick"), verdicts[name], f"{name}'s rule", "quick")
              for name in requires}
    return claims, judged


def test_a_failure_down_a_chain_of_baseline_checks_reaches_the_comparison() -> None:
    claims, judged = chain({"method": REPRODUCED, "baseline": REPRODUCED, "sac": NOT_REPRODUCED})
    final = gate_all(claims, judged)
    assert final["sac"] == (NOT_REPRODUCED, "sac's rule")
    assert final["baseline"][0] == NOT_MADE and final["baseline"][1].startswith("its baseline check 'sac' is not "
                                                                                "reproduced (sac 1.0)")
    outcome, reason = final["method"]
    assert outcome == NOT_MADE, "the comparison reads its check's gated verdict, not its raw one"
    assert reason == ("its baseline check 'baseline' is not made (its own baseline check fails) (baseline 1.0); "
                      "its own reading: reproduced, method's rule")


def test_a_chain_that_holds_leaves_each_verdict_its_own_and_notes_an_open_check() -> None:
    claims, judged = chain({"method": REPRODUCED, "baseline": REPRODUCED, "sac": REPRODUCED})
    assert gate_all(claims, judged) == {name: (REPRODUCED, f"{name}'s rule") for name in ("method", "baseline", "sac")}
    claims, judged = chain({"method": REPRODUCED, "baseline": REPRODUCED, "sac": INCONCLUSIVE})
    final = gate_all(claims, judged)
    assert final["baseline"] == (REPRODUCED, "baseline's rule; its baseline check 'sac' is inconclusive")
    assert final["method"] == (REPRODUCED, "method's rule")


def test_a_chain_of_baseline_checks_that_leads_back_is_refused_naming_the_line(tmp_path: Path) -> None:
    paper = tmp_path / "paper"
    paper.mkdir()
    with (PAPER_DIR / "claims.csv").open(newline="") as file:
        rows = list(csv.DictReader(file))
    read_claims(PAPER_DIR)  # the shipped table has no cycle
    check = next(i for i, row in enumerate(rows) if row["claim"] == DBC_CHECK)
    first = next(i for i, row in enumerate(rows) if row["requires"] == DBC_CHECK)  # the cycle's first row
    rows[check]["requires"] = rows[first]["claim"]  # the check now waits on a comparison that waits on it
    with (paper / "claims.csv").open("w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    cycle = rf"claims.csv line {first + 2}: requires .* leads back to .*a cycle of baseline"
    with pytest.raises(ValueError, match=cycle):
        read_claims(paper)
