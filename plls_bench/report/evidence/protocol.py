"""The declared decision protocol: how two arms' per-trial scores become a verdict.

Pure functions over arrays (trials on the last axis); docs/verdicts.md says why each rule holds.

- Two arms are compared by Welch's t statistic (Colas et al. 2018). A decision reads the larger of
  two two-sided p values of it: its permutation p (every split of the pooled trials into the two
  arms, or 10,000 seeded random ones beyond 20,000 splits) and its t-distribution p
  (Welch-Satterthwaite df). Neither holds its level alone at 5 to 10 trials per arm: the
  permutation p rejects 9-12% of equal means at nominal 5% when the arms' spreads differ (SD ratio
  4 to 77; it is exact only for identical arms), and both put more than alpha / 2 in one direction
  when 20% of the seeds fail at 5 + 10 trials. The larger of the two keeps both
  (tests/test_verdict_calibration.py), at about one point of power. Rows show both.
- A family of such rows is corrected by Holm's step-down method (:func:`holm`).
- "equivalent" is two one-sided Welch tests (TOST) against a margin the claim declares.
- Fewer than ``min_n`` trials in either arm: no test, "too few trials".
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from scipy import stats

from plls_bench.report.evidence.looks import least_rejecting_n

ALPHA = 0.05      # two-sided level of every test (Colas et al. 2018)
MIN_N = 5         # fewest trials per arm a comparison is judged on
POWER = 0.8       # the power the planner asks for
MAX_PLANNED_N = 1000  # the planner's search stops here: beyond it reads "more than 1000"
EXACT_SPLITS = 20_000  # up to this many splits (8 + 8 trials) the permutation p is exact
PERMUTATIONS = 10_000  # random splits beyond that: p's Monte Carlo error about 0.002 at 0.05
PERMUTATION_SEED = 0
DIRECTIONS = ("greater", "less")
A_BETTER, B_BETTER, EQUIVALENT, UNDECIDED, TOO_FEW = (
    "a better", "b better", "equivalent", "undecided", "too few trials")


@dataclass(frozen=True)
class Comparison:
    """Arm a against arm b. ``p`` is the two-sided p a decision reads, the larger of Welch's t's
    (``statistic``) permutation p (``p_permutation``) and t-distribution p (``p_welch``), before any
    family correction (``p_adjusted`` after it; NaN until :func:`adjust` sets it).
    ``effect`` is mean(a) - mean(b). ``outcome``
    is read in the claim's ``direction``: "a better" when a is significantly greater
    (``direction="greater"``) or smaller (``"less"``) than b."""

    n_a: int
    n_b: int
    test: str
    statistic: float       # Welch's t
    p: float
    p_welch: float
    p_permutation: float
    effect: float
    mean_a: float
    mean_b: float
    sd_a: float            # sample SDs (ddof=1; NaN for one trial)
    sd_b: float
    p_equivalence: float   # TOST p against ``margin`` (NaN without one)
    margin: float | None
    direction: str
    alpha: float
    p_adjusted: float
    outcome: str
    n_for_power: int | None
    text: str


# --------------------------------------------------------------------------- tests
def _welch_moments(n: int, m: int, sum_a: np.ndarray, sq_a: np.ndarray, sum_b: np.ndarray,
                   sq_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Welch's t and degrees of freedom from each arm's sum and sum of squares (any shape).
    Zero standard error: t = 0 where the means agree, else +-inf."""
    mean_a, mean_b = sum_a / n, sum_b / m
    va = np.maximum(sq_a - n * mean_a ** 2, 0.0) / (n - 1) / n
    vb = np.maximum(sq_b - m * mean_b ** 2, 0.0) / (m - 1) / m
    diff, se2 = mean_a - mean_b, va + vb
    scale = np.maximum(np.abs(mean_a), np.abs(mean_b))
    zero = se2 <= (1e-12 * scale) ** 2   # rounding left over from identical values
    flat = np.abs(diff) <= 1e-12 * scale
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(zero, np.where(flat, 0.0, np.sign(diff) * np.inf), diff / np.sqrt(se2))
        df = np.where(zero, n + m - 2.0, se2 ** 2 / (va ** 2 / (n - 1) + vb ** 2 / (m - 1)))
    return t, df


def welch(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Welch's t, its degrees of freedom and its two-sided p from the t distribution, over the
    last axis: ``a`` ``(..., n)``, ``b`` ``(..., m)``, each result ``(...)``."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    t, df = _welch_moments(a.shape[-1], b.shape[-1], a.sum(-1), (a ** 2).sum(-1), b.sum(-1), (b ** 2).sum(-1))
    return t, df, np.where(np.isinf(t), 0.0, 2.0 * stats.t.sf(np.abs(np.nan_to_num(t)), df))


@lru_cache(maxsize=64)
def _splits(total: int, n_a: int) -> tuple[np.ndarray, bool]:
    """Which ``n_a`` of ``total`` pooled trials go to arm a: every split ``(C, total)`` when there
    are at most EXACT_SPLITS (exact), else PERMUTATIONS random ones (seeded, so a row always gets
    the same p)."""
    if math.comb(total, n_a) <= EXACT_SPLITS:
        chosen = np.array(list(itertools.combinations(range(total), n_a)))
        exact = True
    else:
        rng = np.random.default_rng(PERMUTATION_SEED)
        chosen = np.argsort(rng.random((PERMUTATIONS, total)), axis=1)[:, :n_a]
        exact = False
    member = np.zeros((len(chosen), total))
    np.put_along_axis(member, chosen, 1.0, axis=1)
    return member, exact


def permutation_p(a: np.ndarray, b: np.ndarray, *, batch: int = 256) -> np.ndarray:
    """Two-sided permutation p of Welch's t over the last axis (``a`` ``(..., n)``, ``b``
    ``(..., m)``; result ``(...)``): the share of splits of the pooled trials into n + m whose
    |t| is at least the observed one; exact over every split, or (k + 1) / (B + 1) over B
    random ones."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    shape = np.broadcast_shapes(a.shape[:-1], b.shape[:-1])
    n, m = a.shape[-1], b.shape[-1]
    pooled = np.concatenate([np.broadcast_to(a, (*shape, n)), np.broadcast_to(b, (*shape, m))], -1)
    pooled = pooled.reshape(-1, n + m)
    pooled = pooled - pooled.mean(axis=1, keepdims=True)  # t is shift-free; this keeps sums exact
    member, exact = _splits(n + m, n)
    p = np.empty(len(pooled))
    for lo in range(0, len(pooled), batch):
        x = pooled[lo:lo + batch]
        total, total_sq = x.sum(1, keepdims=True), (x ** 2).sum(1, keepdims=True)
        sum_a, sq_a = x @ member.T, (x ** 2) @ member.T
        t, _ = _welch_moments(n, m, sum_a, sq_a, total - sum_a, total_sq - sq_a)
        observed, _ = _welch_moments(n, m, x[:, :n].sum(1), (x[:, :n] ** 2).sum(1), x[:, n:].sum(1),
                                     (x[:, n:] ** 2).sum(1))
        beyond = (np.abs(t) >= np.abs(observed)[:, None] * (1 - 1e-9)).sum(1)
        p[lo:lo + batch] = beyond / len(member) if exact else (beyond + 1) / (len(member) + 1)
    return p.reshape(shape)


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
    """Fewest trials per arm (at least ``min_n``, and at least the n at which the protocol's p can
    reach ``alpha`` at all: its permutation floor) at which the protocol's Welch test reaches
    ``power`` for a true difference ``effect`` with SDs ``sd_a``, ``sd_b``; None when there is
    no difference to find, or when it would take more than MAX_PLANNED_N."""
    if not effect or not math.isfinite(effect):
        return None
    for n in range(max(min_n, 2, least_rejecting_n(alpha)), MAX_PLANNED_N + 1):
        if welch_power(effect, sd_a, sd_b, n, alpha) >= power:
            return n
    return None


# --------------------------------------------------------------------------- decisions
def decide_many(effect: np.ndarray, p: np.ndarray, p_equivalence: np.ndarray, direction: str,
                alpha: float = ALPHA) -> np.ndarray:
    """Outcomes of tested comparisons, elementwise over arrays of one shape: a significant
    difference (``p`` <= ``alpha``, after any family correction) in the claim's ``direction``
    ("a better") or against it ("b better"); else "equivalent" where TOST rejects; else "undecided"."""
    effect, p, p_equivalence = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (effect, p, p_equivalence)))
    claimed = effect > 0 if direction == "greater" else effect < 0
    significant = np.where(claimed, A_BETTER, B_BETTER)
    return np.where(p <= alpha, significant, np.where(p_equivalence <= alpha, EQUIVALENT, UNDECIDED))


def decide(effect: float, p: float, p_equivalence: float, direction: str, alpha: float = ALPHA) -> str:
    """:func:`decide_many` of one comparison."""
    return str(decide_many(np.array(effect), np.array(p), np.array(p_equivalence), direction, alpha))


def arm_tests(a: np.ndarray, b: np.ndarray, margin: float | None = None) -> dict[str, np.ndarray]:
    """The protocol's tests over the last axis (``a`` ``(..., n)``, ``b`` ``(..., m)``; each result
    ``(...)``): ``effect`` (mean(a) - mean(b)), Welch's ``t``, its t-distribution ``p_welch`` and
    permutation ``p_permutation``, the larger of the two, ``p``, that a decision reads, and the TOST
    ``p_equivalence`` (NaN without a margin)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    t, _, p_welch = welch(a, b)
    p_eq = equivalence_p(a, b, margin) if margin is not None else np.full(np.shape(t), np.nan)
    p_permutation = permutation_p(a, b)
    return {"effect": a.mean(axis=-1) - b.mean(axis=-1), "t": t, "p_welch": p_welch,
            "p_permutation": p_permutation, "p": np.maximum(p_permutation, p_welch), "p_equivalence": p_eq}


def decisions(a: np.ndarray, b: np.ndarray, *, direction: str = "greater", margin: float | None = None,
              alpha: float = ALPHA, min_n: int = MIN_N) -> tuple[np.ndarray, np.ndarray]:
    """Outcomes and p of many comparisons at once, each on its own (no family correction): ``a``
    ``(..., n)`` against ``b`` ``(..., m)``, results ``(...)``. What :func:`compare_arms` decides
    one comparison by, so a simulation of the rules runs the rules themselves."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    shape = np.broadcast_shapes(a.shape[:-1], b.shape[:-1])
    if min(a.shape[-1], b.shape[-1]) < max(min_n, 2):
        return np.full(shape, TOO_FEW), np.full(shape, np.nan)
    tests = arm_tests(a, b, margin)
    return decide_many(tests["effect"], tests["p"], tests["p_equivalence"], direction, alpha), tests["p"]


def _text(t: float, p: float, p_welch: float, p_permutation: float) -> str:
    return (f"Welch t = {t:.2f}, p = {p:.2g} (the larger of permutation {p_permutation:.2g} "
            f"and t-distribution {p_welch:.2g})")


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
    nan = math.nan
    means = [float(x.mean()) if len(x) else nan for x in (a, b)]
    sds = [float(x.std(ddof=1)) if len(x) > 1 else nan for x in (a, b)]
    effect = means[0] - means[1]
    if min(len(a), len(b)) < max(min_n, 2):
        return Comparison(len(a), len(b), "none", nan, nan, nan, nan, effect, *means, *sds, nan, margin, direction,
                          alpha, nan, TOO_FEW, None,
                          f"not tested: needs {min_n} per arm, has {len(a)} + {len(b)}")
    tests = {key: float(value) for key, value in arm_tests(a, b, margin).items()}
    outcome = decide(tests["effect"], tests["p"], tests["p_equivalence"], direction, alpha)
    n_power = planned_n(effect, sds[0], sds[1], alpha=alpha, min_n=min_n)
    t, p, p_welch, p_permutation = tests["t"], tests["p"], tests["p_welch"], tests["p_permutation"]
    return Comparison(len(a), len(b), "Welch t (larger of permutation and t-distribution p)", t, p, p_welch,
                      p_permutation, effect, *means, *sds, tests["p_equivalence"], margin, direction, alpha,
                      nan, str(outcome), n_power, _text(t, p, p_welch, p_permutation))


def adjust(comparison: Comparison, p_adjusted: float) -> Comparison:
    """``comparison`` decided at its family's corrected p (from :func:`holm`)."""
    if comparison.outcome == TOO_FEW:
        return comparison
    outcome = decide(comparison.effect, p_adjusted, comparison.p_equivalence, comparison.direction,
                     comparison.alpha)
    return replace(comparison, p_adjusted=p_adjusted, outcome=outcome)


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

