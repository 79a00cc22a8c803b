"""The declared decision protocol: how two arms' per-trial scores become a verdict.

Pure functions over arrays (trials on the last axis); docs/verdicts.md says why each rule holds.

- Two arms are compared by Welch's t-test (Colas et al. 2018) *and* the exact two-sided
  Mann-Whitney rank-sum test (its permutation distribution enumerated, ties included). A
  difference counts only when both reject: the row's p is the larger of the two. The exact test
  holds its level whatever the scores' distribution when the arms are identical, so the
  combination does too; Welch's test makes the decision about the means (a rank test alone can
  reject on a difference of shape).
- A family of such rows is corrected by Holm's step-down method (:func:`holm`).
- "equivalent" is two one-sided Welch tests (TOST) against a margin the claim declares.
- Fewer than ``min_n`` trials in either arm: no test, "too few trials".
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Sequence

import numpy as np
from scipy import stats

ALPHA = 0.05      # two-sided level of every test (Colas et al. 2018)
MIN_N = 5         # fewest trials per arm a comparison is judged on
POWER = 0.8       # the power the planner asks for
MAX_PLANNED_N = 1000  # the planner's search stops here: beyond it reads "more than 1000"
DIRECTIONS = ("greater", "less")
A_BETTER, B_BETTER, EQUIVALENT, UNDECIDED, TOO_FEW = (
    "a better", "b better", "equivalent", "undecided", "too few trials")


@dataclass(frozen=True)
class Comparison:
    """Arm a against arm b. ``p`` is two-sided: max(Welch p, exact Mann-Whitney p), before any
    family correction (``p_adjusted`` after it). ``effect`` is mean(a) - mean(b). ``outcome``
    is read in the claim's ``direction``: "a better" when a is significantly greater
    (``direction="greater"``) or smaller (``"less"``) than b."""

    n_a: int
    n_b: int
    test: str
    statistic: float       # Welch's t
    p: float
    p_welch: float
    p_rank: float
    u: float               # Mann-Whitney U of arm a
    effect: float
    p_equivalence: float   # TOST p against ``margin`` (NaN without one)
    margin: float | None
    direction: str
    alpha: float
    p_adjusted: float
    outcome: str
    n_for_power: int | None
    text: str


# --------------------------------------------------------------------------- tests
def welch(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Welch's t, its degrees of freedom and two-sided p over the last axis: ``a`` ``(..., n)``,
    ``b`` ``(..., m)``, each ``(...)``. Both arms constant: t = 0, p = 1 if their means agree,
    else t = +-inf, p = 0."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    n, m = a.shape[-1], b.shape[-1]
    va, vb = a.var(axis=-1, ddof=1) / n, b.var(axis=-1, ddof=1) / m
    diff = a.mean(axis=-1) - b.mean(axis=-1)
    se = np.sqrt(va + vb)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(se > 0, diff / np.where(se > 0, se, 1.0), np.sign(diff) * np.inf)
        df = np.where(se > 0, (va + vb) ** 2 / (va ** 2 / (n - 1) + vb ** 2 / (m - 1)), n + m - 2.0)
    p = np.where(np.isinf(t), 0.0, 2.0 * stats.t.sf(np.abs(np.nan_to_num(t)), df))
    return t, df, p


@lru_cache(maxsize=256)
def _rank_sum_counts(doubled_ranks: tuple[int, ...], n_a: int) -> tuple[np.ndarray, np.ndarray]:
    """The permutation distribution of arm a's doubled rank sum: every sum s that a choice of
    ``n_a`` of the (doubled, so integer) midranks can reach, and how many choices reach it."""
    top = sum(sorted(doubled_ranks)[-n_a:])
    counts = np.zeros((n_a + 1, top + 1))  # counts[k, s]: k ranks chosen, summing to s
    counts[0, 0] = 1.0
    for rank in doubled_ranks:
        counts[1:, rank:] = counts[1:, rank:] + counts[:-1, :top + 1 - rank]
    sums = np.flatnonzero(counts[n_a])
    return sums, counts[n_a, sums]


def rank_test(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mann-Whitney U of ``a`` and the exact two-sided p of the rank-sum test over the last axis
    (``a`` ``(..., n)``, ``b`` ``(..., m)``; each result ``(...)``). Ties take midranks and the
    distribution is that of the tied ranks, enumerated exactly: p = P(|W - E W| >= |w - E W|)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    a, b = np.broadcast_arrays(a[..., :, None], b[..., None, :])
    a, b = a[..., 0], b[..., 0, :]
    n = a.shape[-1]
    pooled = np.concatenate([a, b], axis=-1)
    doubled = np.rint(2 * stats.rankdata(pooled, axis=-1)).astype(int)
    w = doubled[..., :n].sum(axis=-1)
    centre = n * (pooled.shape[-1] + 1)  # E[doubled rank sum]
    p = np.empty(w.shape)
    flat_ranks, flat_w, flat_p = doubled.reshape(-1, pooled.shape[-1]), w.ravel(), p.reshape(-1)
    for row, ranks in enumerate(flat_ranks):
        sums, counts = _rank_sum_counts(tuple(sorted(ranks.tolist())), n)
        extreme = np.abs(sums - centre) >= abs(flat_w[row] - centre)
        flat_p[row] = counts[extreme].sum() / counts.sum()
    u = w / 2.0 - n * (n + 1) / 2.0
    return u, p


def equivalence_p(a: np.ndarray, b: np.ndarray, margin: float) -> np.ndarray:
    """TOST: the larger p of two one-sided Welch tests, H0 mean(a) - mean(b) <= -margin and
    H0 mean(a) - mean(b) >= margin, over the last axis. Small p: the arms are equivalent."""
    t_low, df, _ = welch(np.asarray(a, dtype=float) + margin, b)
    t_high, _, _ = welch(np.asarray(a, dtype=float) - margin, b)
    return np.maximum(stats.t.sf(t_low, df), stats.t.cdf(t_high, df))


def holm(p_values: Sequence[float]) -> np.ndarray:
    """Holm's step-down adjusted p values ``(k,)`` of a family ``(k,)``: reject where the
    adjusted p <= alpha, and the family's chance of any false rejection stays <= alpha. NaN
    entries (rows not tested) stay NaN and do not count towards the family."""
    p = np.asarray(p_values, dtype=float)
    out = np.full(p.shape, np.nan)
    tested = np.flatnonzero(~np.isnan(p))
    order = tested[np.argsort(p[tested], kind="stable")]
    steps = (len(order) - np.arange(len(order))) * p[order]
    out[order] = np.minimum(np.maximum.accumulate(steps), 1.0)
    return out


# --------------------------------------------------------------------------- planning
def welch_power(effect: float, sd_a: float, sd_b: float, n: int, alpha: float = ALPHA) -> float:
    """Power of the two-sided Welch test with ``n`` trials per arm at a true difference of means
    ``effect`` and arm SDs ``sd_a``, ``sd_b`` (noncentral t, Welch-Satterthwaite df)."""
    spread = sd_a ** 2 + sd_b ** 2
    if spread == 0:
        return 1.0 if effect else alpha
    df = (n - 1) * spread ** 2 / (sd_a ** 4 + sd_b ** 4)
    shift = abs(effect) / math.sqrt(spread / n)
    crit = stats.t.ppf(1 - alpha / 2, df)
    return float(stats.nct.sf(crit, df, shift) + stats.nct.cdf(-crit, df, shift))


def planned_n(effect: float, sd_a: float, sd_b: float, *, power: float = POWER,
              alpha: float = ALPHA, min_n: int = MIN_N) -> int | None:
    """Fewest trials per arm (at least ``min_n``) at which the protocol's Welch test reaches
    ``power`` for a true difference ``effect`` with SDs ``sd_a``, ``sd_b``; None when there is
    no difference to find, or when it would take more than MAX_PLANNED_N."""
    if not effect or not math.isfinite(effect):
        return None
    for n in range(max(min_n, 2), MAX_PLANNED_N + 1):
        if welch_power(effect, sd_a, sd_b, n, alpha) >= power:
            return n
    return None


# --------------------------------------------------------------------------- decisions
def decide(effect: float, p: float, p_equivalence: float, direction: str, alpha: float = ALPHA) -> str:
    """The outcome of a tested comparison: a significant difference (``p`` <= ``alpha``, after any
    family correction) in the claim's ``direction`` or against it; else "equivalent" when TOST
    rejects; else "undecided"."""
    if p <= alpha:
        a_higher = effect > 0
        return A_BETTER if a_higher == (direction == "greater") else B_BETTER
    return EQUIVALENT if p_equivalence <= alpha else UNDECIDED


def _text(t: float, p_welch: float, u: float, p_rank: float) -> str:
    return f"Welch t = {t:.3g}, p = {p_welch:.2g}; Mann-Whitney U = {u:g}, exact p = {p_rank:.2g}"


def compare_arms(a: Sequence[float], b: Sequence[float], *, direction: str = "greater",
                 margin: float | None = None, alpha: float = ALPHA, min_n: int = MIN_N) -> Comparison:
    """Compare per-trial scores ``a`` ``(n_a,)`` and ``b`` ``(n_b,)`` under the protocol, one
    comparison on its own (:func:`adjust` applies a family's Holm-corrected p).

    ``direction``: "greater" if the claim is a > b, "less" if a < b. ``margin``: the claim's
    equivalence margin, in the scores' units (None: no equivalence test)."""
    if direction not in DIRECTIONS:
        raise ValueError(f"direction must be one of {DIRECTIONS}, got {direction!r}")
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.ndim != 1 or b.ndim != 1 or not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise ValueError("compare_arms takes two 1-D arrays of finite per-trial scores")
    effect = float(a.mean() - b.mean()) if len(a) and len(b) else math.nan
    nan = math.nan
    if min(len(a), len(b)) < max(min_n, 2):
        return Comparison(len(a), len(b), "none", nan, nan, nan, nan, nan, effect, nan, margin, direction,
                          alpha, nan, TOO_FEW, None,
                          f"not tested: needs {min_n} per arm, has {len(a)} + {len(b)}")
    t, _, p_welch = (float(v) for v in welch(a, b))
    u, p_rank = (float(v) for v in rank_test(a, b))
    p = max(p_welch, p_rank)
    p_eq = float(equivalence_p(a, b, margin)) if margin is not None else nan
    n_power = planned_n(effect, float(a.std(ddof=1)), float(b.std(ddof=1)), alpha=alpha, min_n=min_n)
    return Comparison(len(a), len(b), "Welch t + exact Mann-Whitney", t, p, p_welch, p_rank, u, effect,
                      p_eq, margin, direction, alpha, p, decide(effect, p, p_eq, direction, alpha),
                      n_power, _text(t, p_welch, u, p_rank))


def adjust(comparison: Comparison, p_adjusted: float) -> Comparison:
    """``comparison`` decided at its family's corrected p (from :func:`holm`)."""
    if comparison.outcome == TOO_FEW:
        return comparison
    outcome = decide(comparison.effect, p_adjusted, comparison.p_equivalence, comparison.direction,
                     comparison.alpha)
    return replace(comparison, p_adjusted=p_adjusted, outcome=outcome)


def holm_family(comparisons: Sequence[Comparison]) -> list[Comparison]:
    """Each comparison of a family decided at its Holm-corrected p."""
    adjusted = holm([c.p if c.outcome != TOO_FEW else math.nan for c in comparisons])
    return [adjust(c, float(p)) for c, p in zip(comparisons, adjusted)]


# --------------------------------------------------------------------------- one arm
def t_interval(x: Sequence[float], confidence: float = 1 - ALPHA) -> tuple[float, float]:
    """Two-sided Student t confidence interval of the mean of ``x`` ``(n,)``; NaN for n < 2."""
    x = np.asarray(x, dtype=float)
    if len(x) < 2:
        return math.nan, math.nan
    half = stats.t.ppf(0.5 + confidence / 2, len(x) - 1) * x.std(ddof=1) / math.sqrt(len(x))
    return float(x.mean() - half), float(x.mean() + half)


def one_sample_p(x: Sequence[float], value: float, direction: str = "greater") -> float:
    """One-sided one-sample t-test p that the mean of ``x`` ``(n,)`` lies beyond ``value`` in
    ``direction``; NaN for n < 2. Constant ``x``: 0 if beyond, else 1."""
    x = np.asarray(x, dtype=float)
    if len(x) < 2:
        return math.nan
    sign = 1.0 if direction == "greater" else -1.0
    sd = x.std(ddof=1)
    if sd == 0:
        return 0.0 if sign * (x.mean() - value) > 0 else 1.0
    return float(stats.t.sf(sign * (x.mean() - value) / (sd / math.sqrt(len(x))), len(x) - 1))


def tail_mean(curve: np.ndarray, tail: int) -> np.ndarray:
    """Mean over the last ``tail`` evaluations of each curve: ``curve`` ``(..., P)`` -> ``(...)``."""
    curve = np.asarray(curve, dtype=float)
    if tail < 1:
        raise ValueError(f"tail must be at least 1 evaluation, got {tail}")
    return curve[..., -tail:].mean(axis=-1)


def dispersion_scores(x: Sequence[float]) -> np.ndarray:
    """Brown-Forsythe's absolute deviations from the median, ``(n,)``: comparing two arms' spread
    is comparing these with :func:`compare_arms` (Levene's test with the median)."""
    x = np.asarray(x, dtype=float)
    return np.abs(x - np.median(x))
