"""A row's verdict counts once, at its planned n (docs/verdicts.md, "One look per row"): the claims
table is regenerated at every count the campaign reaches, so a protocol that kept the first
rejection among those counts would be optional stopping.

Simulated identical arms run through the protocol's own decision function
(:func:`plls_bench.report.evidence.protocol.decisions`) at every count a campaign passes through:

- reading a verdict at each count from 5 to 10 per arm puts a false "reproduced" well above alpha / 2
  (the simulation can see the inflation the rule exists to stop);
- the protocol's looks (:func:`~plls_bench.report.evidence.looks.look`: interim below the planned n)
  keep it within alpha / 2 plus Monte Carlo error;
- an arm holding more trials than a row planned (another row asked for them) enters with the seeds
  its plan names, 0 to planned n - 1 (:func:`~plls_bench.report.evidence.looks.planned_seeds`), so the
  counts after the plan are one look, not several.

Making every count from the minimum a final look, or letting trials past the plan enter, fails one
of these.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from plls_bench.report.collect import PAPER_DIR
from plls_bench.report.evidence.claim_settings import load_settings
from plls_bench.report.evidence.looks import (
    FINAL_LOOK,
    INTERIM_LOOK,
    TOO_FEW_LOOK,
    least_rejecting_n,
    look,
    planned_seeds,
)
from plls_bench.report.evidence.protocol import A_BETTER, ALPHA, MIN_N, decisions, holm

SIMULATIONS = 2000
MOST = 10  # the most trials per arm a campaign reaches (the paper's CarRacing count)


def _bound(rate: float) -> float:
    """``rate`` plus three Monte Carlo standard errors of a proportion near it."""
    return rate + 3 * math.sqrt(rate * (1 - rate) / SIMULATIONS)


@pytest.fixture(scope="module")
def null_decisions() -> dict[str, np.ndarray]:
    """Identical normal arms of ``MOST`` trials each, in seed order, ``(SIMULATIONS, MOST)``."""
    rng = np.random.default_rng(2026)
    return {"a": rng.normal(size=(SIMULATIONS, MOST)), "b": rng.normal(size=(SIMULATIONS, MOST))}


def _false_reproduced(arms: dict[str, np.ndarray], planned: int) -> tuple[float, float]:
    """(rate reading every count from the minimum, rate under the protocol's looks) of a false
    "reproduced" in simulations that pass through every count from ``MIN_N`` to ``MOST``."""
    every = np.zeros(SIMULATIONS, dtype=bool)
    protocol = np.zeros(SIMULATIONS, dtype=bool)
    for n in range(MIN_N, MOST + 1):
        finished = np.arange(MOST) < n  # the trials finished when the table is regenerated at n per arm
        kept = planned_seeds(finished, np.arange(MOST), planned)
        rejects = decisions(arms["a"][:, kept], arms["b"][:, kept])[0] == A_BETTER
        # below the plan the protocol keeps every finished trial, so that test is reading every count's
        every |= rejects if (kept == finished).all() else (
            decisions(arms["a"][:, finished], arms["b"][:, finished])[0] == A_BETTER)
        if look(int(kept.sum()), int(kept.sum()), planned, MIN_N) == FINAL_LOOK:
            protocol |= rejects
    return float(every.mean()), float(protocol.mean())


@pytest.mark.parametrize("planned", [MOST, 7])
def test_one_look_per_row_keeps_the_level_that_reading_every_count_loses(null_decisions, planned: int) -> None:
    every, protocol = _false_reproduced(null_decisions, planned)
    print(f"\nplanned n = {planned}: false 'reproduced' reading every count 5-{MOST}: {every:.4f}; "
          f"under the protocol's looks: {protocol:.4f} (bound {_bound(ALPHA / 2):.4f})")
    assert every > _bound(ALPHA / 2), "the simulation should show optional stopping's inflation"
    assert protocol <= _bound(ALPHA / 2)


def test_a_look_is_too_few_then_interim_then_final() -> None:
    assert [look(n, n, 8, 5) for n in (3, 5, 7, 8, 10)] == [TOO_FEW_LOOK, INTERIM_LOOK, INTERIM_LOOK,
                                                           FINAL_LOOK, FINAL_LOOK]
    assert look(10, 7, 8, 5) == INTERIM_LOOK  # the arm with fewer trials decides
    assert look(5, 5, None, 5) == look(5, 5, 3, 5) == FINAL_LOOK  # no plan, or one below the minimum


def test_planned_seeds_keeps_the_seeds_a_plan_names() -> None:
    finished = np.array([True, False, True, True, True])  # seed 1 still running
    seeds = np.arange(5)
    assert planned_seeds(finished, seeds, 3).tolist() == [True, False, True, False, False]  # seed 3 never stands in
    assert planned_seeds(finished, seeds, None).tolist() == finished.tolist()
    assert planned_seeds(finished, seeds, 9).tolist() == finished.tolist()
    assert planned_seeds(finished, np.array([0, 1, 2, 3, 7]), 6).tolist() == [True, False, True, True, False]


def test_a_plan_that_cannot_reject_is_refused_naming_its_key(tmp_path: Path) -> None:
    # 0.05 / 16 primary rows needs 6 + 6 (2 / C(12, 6) = 0.0022); at 0.05, 4 + 4 would do (min_n asks 5)
    assert least_rejecting_n(ALPHA / 16) == 6 and least_rejecting_n(ALPHA) == 4
    text = (PAPER_DIR / "claims.yaml").read_text()
    row = "PL-LS (V_s + V_a) beats PPO + V_s only (final return)"
    start = text.index(f'"{row}":')
    at = text.index("planned_n: 6", start)
    (tmp_path / "claims.yaml").write_text(text[:at] + "planned_n: 5" + text[at + len("planned_n: 6"):])
    with pytest.raises(ValueError, match=re.escape(f"comparisons.{row}.planned_n: 5 trials per arm cannot decide")):
        load_settings(tmp_path, None)


def test_no_holm_adjusted_p_rises_when_another_row_s_p_falls() -> None:
    """Holm over the fixed family (rows not yet judged at p = 1): a row reaching its planned n can
    only lower the others' adjusted p, so no verdict weakens as trials arrive (docs/verdicts.md)."""
    rng = np.random.default_rng(7)
    for _ in range(500):
        p = np.where(rng.random(16) < 0.5, 1.0, rng.random(16) ** 3)  # half the family not yet judged
        row = int(rng.integers(16))
        lowered = p.copy()
        lowered[row] = p[row] * rng.random()
        others = np.arange(16) != row
        assert (holm(lowered)[others] <= holm(p)[others] + 1e-15).all()
