"""Statistics over trials: curve bands, rliable's IQM / mean / probability of improvement with
95% stratified-bootstrap confidence intervals, and the convergence point of Table 3.

Pure functions over arrays; "trials" are always axis 0. Point estimates come from
``rliable.metrics`` (rliable 1.2.0). Its bootstrap module (``rliable.library``) cannot be imported
with the pinned stack (its dependency ``arch`` 7.2 calls a pandas 2 API that pandas 3.1 removed,
and ``arch`` 8 breaks rliable), so the confidence intervals come from :func:`bootstrap_ci`, the
same method: percentile bootstrap, trials resampled with replacement independently within each
stratum (each method's trials), fixed random state.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import scipy.stats
from rliable import metrics

SEED = 0                      # fixed random state of every bootstrap
CONFIDENCE = 0.95             # two-sided percentile interval
SCORE_RESAMPLES = 10_000      # for scalar scores (final return, IQM, P(improvement), MSE)
CURVE_RESAMPLES = 2_000       # per-evaluation bands and curve-level statistics
CONVERGENCE_WINDOW = 5        # evaluations in the trailing smoothing window (Table 3)
CONVERGENCE_TOLERANCE = 0.05  # "within 5% of its final value" (PAPER_SPEC, Table 3)
_CHUNK = 500                  # resamples per vectorised batch, bounds memory on long curves

Interval = tuple[float, float]


# --------------------------------------------------------------------------- bootstrap
def bootstrap_ci(samples: Sequence[np.ndarray], statistic: Callable[..., np.ndarray], *,
                 n_resamples: int = SCORE_RESAMPLES, vectorized: bool = True,
                 seed: int = SEED) -> tuple[np.ndarray, np.ndarray]:
    """Percentile CI of ``statistic(*samples)``, resampling each sample's trials (axis 0)
    independently. Sample i has shape ``(n_i, ...)``. Vectorised statistics get a leading batch
    axis, ``(B, n_i, ...)``, and return ``(B, ...)``; others get one resample at a time. Returns
    (low, high) shaped like the statistic; NaN when a sample has fewer than 2 trials."""
    samples = [np.asarray(s, dtype=float) for s in samples]
    if min(len(s) for s in samples) < 2:
        shape = np.shape(statistic(*samples) if not vectorized else statistic(*[s[None] for s in samples])[0])
        return np.full(shape, np.nan), np.full(shape, np.nan)
    rng = np.random.default_rng(seed)
    values = []
    for start in range(0, n_resamples, _CHUNK):
        batch = min(_CHUNK, n_resamples - start)
        draws = [s[rng.integers(0, len(s), size=(batch, len(s)))] for s in samples]
        if vectorized:
            values.append(np.asarray(statistic(*draws), dtype=float))
        else:
            values.append(np.array([statistic(*[d[b] for d in draws]) for b in range(batch)], dtype=float))
    stack = np.concatenate(values, axis=0)
    tail = 100 * (1 - CONFIDENCE) / 2
    # inverted_cdf picks resampled values themselves: no interpolation, so +inf ("never") is exact
    return (np.percentile(stack, tail, axis=0, method="inverted_cdf"),
            np.percentile(stack, 100 - tail, axis=0, method="inverted_cdf"))


# --------------------------------------------------------------------------- scores
@dataclass(frozen=True)
class ScoreSummary:
    """Mean and IQM of per-trial scores with their 95% CIs (NaN bounds for fewer than 2 trials)."""

    n: int
    mean: float
    mean_ci: Interval
    iqm: float
    iqm_ci: Interval
    std: float


def summarise(scores: np.ndarray) -> ScoreSummary:
    """``scores``: ``(n_trials,)``, one score per trial (e.g. final mean return)."""
    scores = np.asarray(scores, dtype=float)
    column = scores[:, None]  # rliable's (num_runs, num_tasks) layout, one task
    mean_lo, mean_hi = bootstrap_ci([scores], lambda s: s.mean(axis=-1))
    iqm_lo, iqm_hi = bootstrap_ci([scores], _iqm_batched)
    return ScoreSummary(len(scores), float(metrics.aggregate_mean(column)), (float(mean_lo), float(mean_hi)),
                        float(metrics.aggregate_iqm(column)), (float(iqm_lo), float(iqm_hi)),
                        float(np.std(scores, ddof=1)) if len(scores) > 1 else 0.0)


def probability_of_improvement(x: np.ndarray, y: np.ndarray) -> tuple[float, Interval]:
    """P(X > Y) + P(X = Y) / 2 for one trial of each, over ``x`` ``(n,)`` and ``y`` ``(m,)``
    (rliable's definition), with its stratified-bootstrap CI."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    point = float(metrics.probability_of_improvement(x[:, None], y[:, None]))
    lo, hi = bootstrap_ci([x, y], _poi_batched)
    return point, (float(lo), float(hi))


def _iqm_batched(s: np.ndarray) -> np.ndarray:
    return scipy.stats.trim_mean(s, 0.25, axis=-1)


def _poi_batched(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(B, n), (B, m) -> (B,): the Mann-Whitney U statistic over n * m, as rliable computes it."""
    diff = x[..., :, None] - y[..., None, :]
    return ((diff > 0) + 0.5 * (diff == 0)).mean(axis=(-2, -1))


# --------------------------------------------------------------------------- curves
def align(curves: Sequence[tuple[np.ndarray, np.ndarray]], interpolate: bool = False,
          points: int = 50) -> tuple[np.ndarray, np.ndarray]:
    """Put trials' curves ``(x_i, y_i)`` on one grid: ``(grid (P,), values (n_trials, P))``.
    Exact x values (iterations, env steps) are matched; with ``interpolate`` (wall time) each
    trial is interpolated linearly on ``points`` evenly spaced x within its own range. NaN marks
    a grid point a trial does not reach."""
    if not curves:
        return np.zeros(0), np.zeros((0, 0))
    if interpolate:
        grid = np.linspace(0.0, max(float(x.max()) for x, _ in curves if len(x)), points)
    else:
        grid = np.unique(np.concatenate([x for x, _ in curves]))
    values = np.full((len(curves), len(grid)), np.nan)
    for row, (x, y) in enumerate(curves):
        if len(x) == 0:
            continue
        if interpolate:
            inside = (grid >= x.min()) & (grid <= x.max())
            values[row, inside] = np.interp(grid[inside], x, y)
        else:
            values[row, np.searchsorted(grid, x)] = y
    return grid, values


def band(values: np.ndarray) -> dict[str, np.ndarray]:
    """Per grid point over the trials present (non-NaN) in ``values`` ``(n_trials, P)``: ``n``,
    ``mean``, ``std`` (sample std, ddof=1; 0 for one trial) and the 95% bootstrap CI of the mean
    (NaN for one trial). Columns with the same trials present share one bootstrap."""
    present = ~np.isnan(values)
    n = present.sum(axis=0)
    out = {"n": n, "mean": np.full(len(n), np.nan), "std": np.full(len(n), np.nan),
           "ci_low": np.full(len(n), np.nan), "ci_high": np.full(len(n), np.nan)}
    patterns: dict[bytes, list[int]] = {}
    for col in range(values.shape[1]):
        patterns.setdefault(present[:, col].tobytes(), []).append(col)
    for cols in patterns.values():
        block = values[present[:, cols[0]]][:, cols]  # (trials present, columns)
        if len(block) == 0:
            continue
        out["mean"][cols] = block.mean(axis=0)
        out["std"][cols] = block.std(axis=0, ddof=1) if len(block) > 1 else 0.0
        lo, hi = bootstrap_ci([block], lambda s: s.mean(axis=-2), n_resamples=CURVE_RESAMPLES)
        out["ci_low"][cols], out["ci_high"][cols] = lo, hi
    return out


def complete(grid: np.ndarray, *matrices: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """The grid points every trial of every matrix reaches, and the matrices cut to them."""
    keep = np.ones(len(grid), dtype=bool)
    for matrix in matrices:
        keep &= ~np.isnan(matrix).any(axis=0)
    return grid[keep], [m[:, keep] for m in matrices]


# --------------------------------------------------------------------------- convergence
def smooth(y: np.ndarray, window: int = CONVERGENCE_WINDOW) -> np.ndarray:
    """Trailing moving average over the last ``window`` points (fewer at the start)."""
    y = np.asarray(y, dtype=float)
    csum = np.concatenate([[0.0], np.cumsum(y)])
    idx = np.arange(1, len(y) + 1)
    start = np.maximum(idx - window, 0)
    return (csum[idx] - csum[start]) / (idx - start)


def convergence_index(y: np.ndarray, window: int = CONVERGENCE_WINDOW,
                      tolerance: float = CONVERGENCE_TOLERANCE) -> int | None:
    """Table 3's convergence point of a mean-return curve ``y`` ``(P,)`` (one value per
    evaluation). With s = :func:`smooth` (trailing mean over ``window`` evaluations) and
    final = s[-1], it is the first evaluation t such that |s[u] - final| <= tolerance * |final|
    for every u >= t. A curve whose stable tail is shorter than ``window`` evaluations has not
    shown a plateau within its budget: None (not converged)."""
    if len(y) == 0:
        return None
    s = smooth(y, window)
    inside = np.abs(s - s[-1]) <= tolerance * abs(s[-1])
    outside = np.flatnonzero(~inside)
    first = int(outside[-1]) + 1 if len(outside) else 0
    return first if len(s) - first >= window else None


def ahead_from(mean_a: np.ndarray, mean_b: np.ndarray) -> int | None:
    """First index from which ``mean_a`` stays strictly above ``mean_b`` to the end; None if it
    is not ahead at the last point. Both ``(P,)`` on one grid."""
    behind = np.flatnonzero(~(np.asarray(mean_a) > np.asarray(mean_b)))
    if len(behind) and behind[-1] == len(mean_a) - 1:
        return None
    return int(behind[-1]) + 1 if len(behind) else 0
