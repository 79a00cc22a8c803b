"""The collector's statistics on hand-made numbers: convergence (Table 3's rule), curve bands,
bootstrap CIs (exact cases, exact enumeration, scipy), IQM and probability of improvement."""
from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import scipy.stats
from rliable import metrics

from plls_bench.report.evidence.stats import (
    _mean_and_iqm,
    _poi,
    ahead_from,
    align,
    band,
    bootstrap_ci,
    convergence_index,
    probability_of_improvement,
    smooth,
    summarise,
)
from plls_bench.report.evidence.table_formats import Table, fmt, fmt_ci, tex


def test_smooth_is_a_trailing_mean() -> None:
    assert smooth(np.array([0, 10, 20, 30, 40, 50.0]), window=3).tolist() == [0, 5, 10, 20, 30, 40]


def test_convergence_of_a_step_curve_computed_by_hand() -> None:
    # trailing means over 5: 0, 25, 46.7, 60, 68, 88, 98, 100, ...; final 100; 5% band [95, 105]:
    # 88 (index 5) is outside, everything from index 6 inside, and 6 evaluations remain.
    assert convergence_index(np.array([0, 50, 90] + [100.0] * 9)) == 6


def test_convergence_needs_a_stable_tail_of_one_window() -> None:
    y = [0.0] * 6 + [100.0] * 9  # smoothed reaches 100 at index 10; 5 evaluations from there
    assert convergence_index(np.array(y)) == 10
    assert convergence_index(np.array(y[:-1])) is None  # only 4 left: no plateau within the budget


def test_a_rising_curve_has_not_converged_and_a_flat_one_converges_at_once() -> None:
    assert convergence_index(np.arange(12) * 10.0) is None
    assert convergence_index(np.full(8, 5.0)) == 0


def test_convergence_of_negative_returns_uses_the_final_value_s_magnitude() -> None:
    # smoothed: -300, -250, -200, -175, -160, -120, -100, ...; band [-105, -95] from index 6
    assert convergence_index(np.array([-300, -200] + [-100.0] * 10)) == 6


def test_ahead_from() -> None:
    b = np.ones(4)
    assert ahead_from(np.array([0, 1, 2, 3.0]), b) == 2
    assert ahead_from(np.array([2, 0, 2, 3.0]), b) == 2
    assert ahead_from(np.array([2, 2, 2, 2.0]), b) == 0
    assert ahead_from(np.array([2, 2, 2, 1.0]), b) is None


def test_bootstrap_ci_of_two_trials_is_exactly_their_range() -> None:
    # resampled means are a, (a+b)/2, b with probabilities 1/4, 1/2, 1/4: the 2.5% and 97.5%
    # quantiles are a and b themselves
    low, high = bootstrap_ci([np.array([3.0, 7.0])], lambda s: s.mean(axis=-1))
    assert (low, high) == (3.0, 7.0)


def test_bootstrap_ci_needs_two_trials() -> None:
    low, high = bootstrap_ci([np.array([3.0])], lambda s: s.mean(axis=-1))
    assert math.isnan(low) and math.isnan(high)


def test_bootstrap_ci_matches_exact_enumeration_of_all_resamples() -> None:
    data = np.array([0.0, 1.0, 3.0, 10.0])
    means = np.sort([data[list(i)].mean() for i in itertools.product(range(4), repeat=4)])  # 256 equally likely
    exact = (np.percentile(means, 2.5, method="inverted_cdf"), np.percentile(means, 97.5, method="inverted_cdf"))
    low, high = bootstrap_ci([data], lambda s: s.mean(axis=-1), n_resamples=20_000)
    assert low == pytest.approx(exact[0], abs=0.26) and high == pytest.approx(exact[1], abs=0.26)  # one 0.25 step


def test_bootstrap_ci_agrees_with_scipy_percentile_bootstrap() -> None:
    data = np.random.default_rng(1).normal(10.0, 2.0, size=8)
    low, high = bootstrap_ci([data], lambda s: s.mean(axis=-1), n_resamples=20_000)
    ref = scipy.stats.bootstrap((data,), np.mean, n_resamples=20_000, method="percentile",
                                random_state=np.random.default_rng(0)).confidence_interval
    assert low == pytest.approx(ref.low, abs=0.1) and high == pytest.approx(ref.high, abs=0.1)


def test_bootstrap_ci_is_reproducible() -> None:
    data = np.random.default_rng(2).normal(size=6)
    assert bootstrap_ci([data], lambda s: s.mean(axis=-1)) == bootstrap_ci([data], lambda s: s.mean(axis=-1))


def test_iqm_and_mean_by_hand() -> None:
    s = summarise(np.array([1, 2, 3, 4, 100, 6, 7, 8.0]))
    assert s.iqm == pytest.approx(5.0)  # middle half: 3, 4, 6, 7
    assert s.mean == pytest.approx(131 / 8)
    assert s.mean_ci[0] < s.mean < s.mean_ci[1] and s.iqm_ci[0] <= s.iqm <= s.iqm_ci[1]


def test_probability_of_improvement_by_hand() -> None:
    p, ci = probability_of_improvement(np.array([3, 4, 5.0]), np.array([1, 2, 3.5]))
    assert p == pytest.approx(8 / 9)  # 3 beats two of three; 4 and 5 beat all
    p_ties, _ = probability_of_improvement(np.array([1, 2.0]), np.array([2, 0.0]))
    assert p_ties == pytest.approx((0 + 1 + 0.5 + 1) / 4)  # a tie counts one half
    assert ci[0] <= p <= ci[1]


def test_probability_of_improvement_equals_rliable() -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        x, y = rng.integers(0, 5, size=6).astype(float), rng.integers(0, 5, size=4).astype(float)
        assert _poi(x[:, None], y[:, None])[0] == pytest.approx(
            metrics.probability_of_improvement(x[:, None], y[:, None]))
    p, ci = probability_of_improvement(x, y)
    assert p == pytest.approx(metrics.probability_of_improvement(x[:, None], y[:, None]))
    assert ci[0] <= p <= ci[1]


def test_resampled_mean_and_iqm_equal_rliable() -> None:
    rng = np.random.default_rng(4)
    for n in (2, 3, 4, 5, 7, 8, 10):
        column = rng.normal(size=(n, 1))
        assert _mean_and_iqm(column) == pytest.approx(
            [metrics.aggregate_mean(column), metrics.aggregate_iqm(column)])


def test_align_matches_exact_x_and_interpolates_wall_time() -> None:
    first, second = (np.array([0, 2, 4.0]), np.array([1, 2, 3.0])), (np.array([0, 2.0]), np.array([5, 6.0]))
    grid, values = align([first, second])
    assert grid.tolist() == [0, 2, 4]
    assert np.array_equal(values, np.array([[1, 2, 3], [5, 6, np.nan]]), equal_nan=True)
    grid, values = align([(np.array([0, 10.0]), np.array([0, 10.0]))], interpolate=True, points=3)
    assert grid.tolist() == [0, 5, 10] and values.tolist() == [[0, 5, 10]]


def test_band_by_hand_with_a_trial_missing_at_the_end() -> None:
    out = band(np.array([[0.0, 20.0, 5.0], [0.0, 80.0, np.nan]]))
    assert out["n"].tolist() == [2, 2, 1]
    assert out["mean"].tolist() == [0, 50, 5]
    assert out["std"][1] == pytest.approx(60 / math.sqrt(2)) and out["std"][2] == 0
    assert (out["ci_low"][1], out["ci_high"][1]) == (20, 80) and math.isnan(out["ci_low"][2])


def test_number_formats_and_latex_escaping() -> None:
    assert [fmt(4e-4), fmt(0.00092), fmt(8710), fmt(0.99), fmt(None), fmt(math.inf)] == [
        "4e-4", "9.2e-4", "8,710", "0.99", "—", "∞"]
    assert fmt_ci(0.5, (0.25, 1.0)) == "0.5 [0.25, 1]" and fmt_ci(3.0, (math.nan, math.nan)) == "3"
    assert tex("a_b & 50% ± x") == r"a\_b \& 50\% $\pm$ x"
    table = Table("T", "cap", ["a", "b|c"], [["1", "2"]])
    assert table.markdown().splitlines()[2] == "| a | b\\|c |"
    assert r"\begin{tabular}{|l|c|}" in table.latex("t") and table.csv() == "a,b|c\n1,2\n"


def test_plateau_epoch_is_the_first_epoch_changing_less_than_1_percent_over_3() -> None:
    import numpy as np

    from plls_bench.report.figures.curves import plateau_epoch

    losses = np.array([100.0, 50, 30, 20, 19.9, 19.8, 19.7, 19.69])  # epochs 1..8
    # index 6: |19.7 - 20| = 0.3 > 0.2; index 7: |19.69 - 19.9| = 0.21 > 0.199: still changing
    assert plateau_epoch(losses) is None
    assert plateau_epoch(np.append(losses, 19.65)) == 8  # |19.65 - 19.8| = 0.15 < 0.198
    assert plateau_epoch(np.array([1.0, 1.0])) is None  # fewer than window + 1 epochs
