"""Statistics over trials: curve bands, rliable's IQM / mean / probability of improvement with
95% stratified-bootstrap confidence intervals, and the convergence point of Table 3.

Pure functions over arrays; "trials" are always axis 0. Point estimates come from
``rliable.metrics`` and every confidence interval from rliable's own stratified bootstrap,
``rliable.library.get_interval_estimates`` (percentile method, each sample's trials resampled
with replacement independently, fixed random state).
"""
from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from rliable import library, metrics

SEED = 0                      # fixed random state of every bootstrap
CONFIDENCE = 0.95             # two-sided percentile interval
SCORE_RESAMPLES = 10_000      # for scalar scores (final return, IQM, P(improvement), MSE)
CURVE_RESAMPLES = 2_000       # per-evaluation bands and curve-level statistics
CONVERGENCE_WINDOW = 5        # evaluations in the trailing smoothing window (Table 3)
CONVERGENCE_TOLERANCE = 0.05  # "within 5% of its final value": docs/decisions.md#d4 (Table 3)
# "Never" (+inf, e.g. a curve that never converges) enters arch's percentile as the largest float:
# its linear interpolation turns inf - inf into NaN. A bound beyond _NEVER_BOUND lies at or
# towards "never" and is reported as inf.
_NEVER = np.finfo(float).max
_NEVER_BOUND = _NEVER * 1e-10

Interval = tuple[float, float]


# --------------------------------------------------------------------------- bootstrap
@contextlib.contextmanager
def _seeded(seed: int) -> Iterator[None]:
    """rliable draws its resamples from numpy's global RNG: seed it, and restore it afterwards
    so that callers' own draws are unaffected."""
    state = np.random.get_state()
    np.random.seed(seed)
    try:
        yield
    finally:
        np.random.set_state(state)


def interval(samples: Sequence[np.ndarray], func: Callable[..., np.ndarray], *,
             n_resamples: int = SCORE_RESAMPLES, seed: int = SEED) -> np.ndarray:
    """rliable's stratified-bootstrap percentile CI of ``func(*samples)`` (a 1-D array), each
    sample's runs resampled independently: ``(2, k)``, lows then highs."""
    with _seeded(seed):
        _, estimates = library.get_interval_estimates(
            {"": list(samples)}, func, reps=n_resamples, confidence_interval_size=CONFIDENCE)
    return np.asarray(estimates[""], dtype=float)


def bootstrap_ci(samples: Sequence[np.ndarray], statistic: Callable[..., np.ndarray], *,
                 n_resamples: int = SCORE_RESAMPLES, vectorized: bool = True,
                 seed: int = SEED) -> tuple[np.ndarray, np.ndarray]:
    """Percentile CI of ``statistic(*samples)``, resampling each sample's trials (axis 0)
    independently. Sample i has shape ``(n_i, ...)``. Vectorised statistics take a leading batch
    axis, ``(1, n_i, ...)``, and return ``(1, ...)``; others take the samples as they are. Returns
    (low, high) shaped like the statistic; NaN when a sample has fewer than 2 trials.

    rliable resamples every entry of a ``(runs, tasks, ...)`` array on its own, which would mix
    trials within a curve; so the bootstrap runs over trial indices (one task), and each draw
    takes whole trials."""
    samples = [np.asarray(s, dtype=float) for s in samples]

    def value(*drawn: np.ndarray) -> np.ndarray:
        out = statistic(*[d[None] for d in drawn])[0] if vectorized else statistic(*drawn)
        return np.asarray(out, dtype=float)

    shape = np.shape(value(*samples))
    if min(len(s) for s in samples) < 2:
        return np.full(shape, np.nan), np.full(shape, np.nan)

    def func(*indices: np.ndarray) -> np.ndarray:
        out = value(*[s[i[:, 0]] for s, i in zip(samples, indices)]).ravel()
        return np.where(np.isposinf(out), _NEVER, out)

    low, high = interval([np.arange(len(s))[:, None] for s in samples], func, n_resamples=n_resamples, seed=seed)
    low, high = (np.where(b > _NEVER_BOUND, np.inf, b).reshape(shape) for b in (low, high))
    return low, high


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


def _mean_and_iqm(column: np.ndarray) -> np.ndarray:
    """rliable's ``aggregate_mean`` and ``aggregate_iqm`` of a ``(runs, 1)`` column, in numpy: the
    bootstrap calls it once per resample, where scipy's ``trim_mean`` costs 20x more."""
    values = np.sort(column, axis=None)
    cut = int(0.25 * len(values))  # scipy's trim_mean: int(proportiontocut * nobs) off each end
    return np.array([values.mean(), values[cut:len(values) - cut].mean()])


def summarise(scores: np.ndarray) -> ScoreSummary:
    """``scores``: ``(n_trials,)``, one score per trial (e.g. final mean return)."""
    scores = np.asarray(scores, dtype=float)
    column = scores[:, None]  # rliable's (num_runs, num_tasks) layout, one task
    mean, iqm = metrics.aggregate_mean(column), metrics.aggregate_iqm(column)
    ci = np.full((2, 2), np.nan)
    if len(scores) > 1:
        ci = interval([column], _mean_and_iqm)
    return ScoreSummary(len(scores), float(mean), (float(ci[0, 0]), float(ci[1, 0])),
                        float(iqm), (float(ci[0, 1]), float(ci[1, 1])),
                        float(np.std(scores, ddof=1)) if len(scores) > 1 else 0.0)


def _poi(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """rliable's ``probability_of_improvement`` of ``(n, 1)`` and ``(m, 1)`` columns: the
    Mann-Whitney U statistic over n * m, in numpy (scipy's ``mannwhitneyu`` per resample is 20x
    slower)."""
    diff = x[:, 0, None] - y[None, :, 0]
    return np.array([((diff > 0) + 0.5 * (diff == 0)).mean()])


def probability_of_improvement(x: np.ndarray, y: np.ndarray) -> tuple[float, Interval]:
    """P(X > Y) + P(X = Y) / 2 for one trial of each, over ``x`` ``(n,)`` and ``y`` ``(m,)``
    (rliable's definition), with its stratified-bootstrap CI."""
    x, y = np.asarray(x, dtype=float)[:, None], np.asarray(y, dtype=float)[:, None]
    point = float(metrics.probability_of_improvement(x, y))
    if min(len(x), len(y)) < 2:
        return point, (np.nan, np.nan)
    (lo,), (hi,) = interval([x, y], _poi)
    return point, (float(lo), float(hi))


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
