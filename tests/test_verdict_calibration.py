"""The verdict rules keep their error rates (issue 63, docs/verdicts.md): simulated arms run through
the protocol's own decision functions (:func:`plls_bench.report.evidence.protocol.decisions`, which
:func:`compare_arms` shares its tests and rule with) and Holm's correction.

- Identical arms (normal, heavy-tailed t with 2 degrees of freedom, and a mixture where 20% of the
  seeds fail) at n = 5, 7, 10 per arm: a false "reproduced" (a significant difference in the claimed
  direction) at most alpha / 2, any significant difference at most alpha, each plus three Monte
  Carlo standard errors.
- Equal means, unequal spreads (normal, SD ratio 4 and 10, n = 5 + 5, 5 + 7, 5 + 10), the same bounds:
  the permutation p alone rejects 7-11% here (it is exact only for identical arms).
- Identical arms at unequal n where 20% of the seeds fail (5 + 10, 8000 simulations for a tighter
  bound): false "reproduced" at most alpha / 2 plus Monte Carlo error. The permutation p alone puts
  about 0.037 in that direction, the t-distribution p alone about 0.042; their larger, about 0.026.
- A family of five identical-arm comparisons under Holm: any false "reproduced" at most alpha.
- A planted effect at the n the planner promises 80% power for: found at that power.
- Two arms exactly one margin apart: "equivalent" at most alpha (TOST's level).

Loosening a rule (a one-sided p, deciding on the permutation p alone or on the t-distribution p
alone, no Holm step, alpha 0.1, a minimum below 5) fails one of these. Seeded and vectorised: seconds
on 2 cores.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from plls_bench.report.evidence import protocol
from plls_bench.report.evidence.protocol import (
    A_BETTER,
    B_BETTER,
    EQUIVALENT,
    TOO_FEW,
    decisions,
    holm,
    planned_n,
    welch_power,
)

ALPHA = protocol.ALPHA
SIMULATIONS = 2000
SIZES = (5, 7, 10)


def _draw(kind: str, rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Trial scores of one arm: ``shape`` ``(simulations, n)``."""
    if kind == "normal":
        return rng.normal(size=shape)
    if kind == "heavy-tailed":
        return rng.standard_t(2, size=shape)
    learned, failed = rng.normal(size=shape), rng.normal(-10.0, 0.5, size=shape)  # a failed seed scores ~ -10
    return np.where(rng.random(shape) < 0.2, failed, learned)


def _bound(rate: float, simulations: int = SIMULATIONS) -> float:
    """``rate`` plus three Monte Carlo standard errors of a proportion near it."""
    return rate + 3 * math.sqrt(rate * (1 - rate) / simulations)


def _null_rates(kind: str, n: int, seed: int) -> tuple[float, float]:
    rng = np.random.default_rng(seed)
    outcome, _ = decisions(_draw(kind, rng, (SIMULATIONS, n)), _draw(kind, rng, (SIMULATIONS, n)))
    reproduced = float(np.mean(outcome == A_BETTER))
    return reproduced, reproduced + float(np.mean(outcome == B_BETTER))


@pytest.fixture(scope="module")
def null_table() -> dict[tuple[str, int], tuple[float, float]]:
    table = {(kind, n): _null_rates(kind, n, seed=100 * i + n)
             for i, kind in enumerate(("normal", "heavy-tailed", "20% failing")) for n in SIZES}
    print("\nfalse 'reproduced' (any significant) per distribution and n per arm, "
          f"{SIMULATIONS} simulations; bounds {_bound(ALPHA / 2):.4f} ({_bound(ALPHA):.4f}):")
    for (kind, n), (reproduced, decisive) in table.items():
        print(f"  {kind:13s} n = {n:2d}: {reproduced:.4f} ({decisive:.4f})")
    return table


@pytest.mark.parametrize("kind", ["normal", "heavy-tailed", "20% failing"])
@pytest.mark.parametrize("n", SIZES)
def test_identical_arms_are_rarely_reproduced(null_table, kind: str, n: int) -> None:
    reproduced, decisive = null_table[kind, n]
    assert reproduced <= _bound(ALPHA / 2), f"false 'reproduced' {reproduced:.4f} at {kind}, n = {n}"
    assert decisive <= _bound(ALPHA), f"false significant differences {decisive:.4f} at {kind}, n = {n}"


UNEQUAL_SPREADS = ((5, 5, 4.0), (5, 5, 10.0), (5, 7, 4.0), (5, 10, 10.0), (10, 5, 10.0))  # n_a, n_b, SD_a / SD_b


@pytest.mark.parametrize(("n_a", "n_b", "ratio"), UNEQUAL_SPREADS)
def test_equal_means_with_unequal_spreads_are_rarely_reproduced(n_a: int, n_b: int, ratio: float) -> None:
    rng = np.random.default_rng(int(10 * n_a + n_b + ratio))
    outcome, _ = decisions(rng.normal(0.0, ratio, (SIMULATIONS, n_a)), rng.normal(0.0, 1.0, (SIMULATIONS, n_b)))
    reproduced, decisive = float(np.mean(outcome == A_BETTER)), float(np.mean(outcome != protocol.UNDECIDED))
    print(f"\nequal means, SD ratio {ratio:g}, n = {n_a} + {n_b}: false 'reproduced' {reproduced:.4f} ({decisive:.4f})")
    assert reproduced <= _bound(ALPHA / 2), reproduced
    assert decisive <= _bound(ALPHA), decisive


def test_failing_seeds_at_unequal_n_are_rarely_reproduced() -> None:
    simulations, rng = 8000, np.random.default_rng(13)
    outcome, _ = decisions(_draw("20% failing", rng, (simulations, 5)), _draw("20% failing", rng, (simulations, 10)))
    reproduced = float(np.mean(outcome == A_BETTER))
    print(f"\n20% failing, identical arms, n = 5 + 10: false 'reproduced' {reproduced:.4f}")
    assert reproduced <= _bound(ALPHA / 2, simulations), reproduced


def test_holm_keeps_a_family_of_identical_arms_at_alpha() -> None:
    rng = np.random.default_rng(7)
    family, families = 5, SIMULATIONS
    a, b = (_draw("20% failing", rng, (families * family, 5)) for _ in range(2))
    outcome, p = decisions(a, b)
    adjusted = np.stack([holm(row) for row in p.reshape(families, family)])
    effects = (a.mean(axis=1) - b.mean(axis=1)).reshape(families, family)
    false_reproduced = float(np.mean(((adjusted <= ALPHA) & (effects > 0)).any(axis=1)))
    print(f"\nHolm, {family} identical-arm comparisons per family: any false 'reproduced' {false_reproduced:.4f}")
    assert false_reproduced <= _bound(ALPHA / 2), false_reproduced  # Holm's bound, one direction
    assert (outcome == A_BETTER).reshape(families, family).any(axis=1).mean() > false_reproduced  # it did correct


@pytest.mark.parametrize("effect", [2.0, 1.5, 1.0])
def test_a_planted_effect_is_found_with_the_promised_power(effect: float) -> None:
    n = planned_n(effect, 1.0, 1.0)
    promised = welch_power(effect, 1.0, 1.0, n)
    rng = np.random.default_rng(int(effect * 10))
    outcome, _ = decisions(rng.normal(effect, 1.0, (SIMULATIONS, n)), rng.normal(0.0, 1.0, (SIMULATIONS, n)))
    power = float(np.mean(outcome == A_BETTER))
    error = 3 * math.sqrt(promised * (1 - promised) / SIMULATIONS)
    print(f"\nplanted effect {effect} SD: planner's n = {n}, promised power {promised:.3f}, found {power:.3f}")
    assert promised >= protocol.POWER
    assert abs(power - promised) <= error + 0.02, (power, promised)


def test_arms_one_margin_apart_are_rarely_called_equivalent() -> None:
    rng = np.random.default_rng(11)
    outcome, _ = decisions(rng.normal(1.0, 1.0, (SIMULATIONS, 10)), rng.normal(0.0, 1.0, (SIMULATIONS, 10)),
                           margin=1.0)
    equivalent = float(np.mean(outcome == EQUIVALENT))
    print(f"\narms one margin apart, n = 10: 'equivalent' {equivalent:.4f}")
    assert equivalent <= _bound(ALPHA)


def test_fewer_than_five_trials_per_arm_are_never_judged() -> None:
    rng = np.random.default_rng(3)
    outcome, _ = decisions(rng.normal(5.0, 1.0, (10, 4)), rng.normal(0.0, 1.0, (10, 9)))
    assert (outcome == TOO_FEW).all()
    row = protocol.compare_arms([9.0, 9.1, 9.2], [0.0, 0.1, 0.2])
    assert (row.outcome, row.text) == (TOO_FEW, "not tested: needs 5 per arm, has 3 + 3")
