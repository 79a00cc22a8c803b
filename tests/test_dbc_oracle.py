"""The exact bisimulation oracle: W_1 against a closed form, the metric on MDPs with known answers."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import wasserstein_distance

from baselines.dbc.oracle import bisimulation_metric, on_policy, wasserstein1


def test_w1_lp_matches_the_closed_form_on_a_line() -> None:
    rng = np.random.default_rng(0)
    points = rng.normal(size=7)
    cost = np.abs(points[:, None] - points[None, :])
    for _ in range(3):
        p, q = rng.dirichlet(np.ones(7)), rng.dirichlet(np.ones(7))
        assert wasserstein1(p, q, cost) == pytest.approx(wasserstein_distance(points, points, p, q), abs=1e-7)


def test_absorbing_states_are_apart_by_their_discounted_reward_gap() -> None:
    rewards, transitions = np.array([0.0, 1.0]), np.eye(2)
    d, _ = bisimulation_metric(rewards, transitions, 0.5)
    assert d[0, 1] == pytest.approx(1.0 / (1 - 0.5), rel=1e-6)


def test_metric_of_a_chain_with_known_answer() -> None:
    # 0 -> 2 and 1 -> 2 deterministically, 2 absorbing: d(0, 1) = |r0 - r1| (same successor);
    # d(0, 2) = |r0 - r2| + gamma d(2, 2) = |r0 - r2|; state 3 copies state 0 (bisimilar).
    rewards = np.array([0.2, 0.7, 0.5, 0.2])
    transitions = np.array([[0, 0, 1, 0], [0, 0, 1, 0], [0, 0, 1, 0], [0, 0, 1, 0]], dtype=float)
    d, _ = bisimulation_metric(rewards, transitions, 0.8)
    assert d[0, 1] == pytest.approx(0.5, abs=1e-6)
    assert d[0, 2] == pytest.approx(0.3, abs=1e-6)
    assert d[0, 3] == pytest.approx(0.0, abs=1e-6)


def test_metric_is_the_fixed_point_and_a_pseudometric() -> None:
    rng = np.random.default_rng(1)
    n, gamma = 6, 0.7
    transitions, rewards = rng.dirichlet(0.5 * np.ones(n), size=n), rng.uniform(size=n)
    d, iterations = bisimulation_metric(rewards, transitions, gamma, tol=1e-8)
    assert iterations > 1
    for s in range(n):
        for t in range(n):  # each entry checked with a fresh single-pair LP
            expected = abs(rewards[s] - rewards[t]) + gamma * wasserstein1(transitions[s], transitions[t], d)
            assert d[s, t] == pytest.approx(expected, abs=1e-6)
    assert np.allclose(d, d.T) and np.allclose(np.diag(d), 0, atol=1e-9)
    assert (d[:, :, None] <= d[:, None, :] + d.T[None, :, :] + 1e-6).all(), "triangle inequality"


def test_on_policy_reduction() -> None:
    rewards = np.array([[1.0, 0.0], [0.0, 2.0]])
    transitions = np.array([[[1.0, 0.0], [0.0, 1.0]], [[0.5, 0.5], [1.0, 0.0]]])
    policy = np.array([[0.25, 0.75], [1.0, 0.0]])
    r_pi, p_pi = on_policy(rewards, transitions, policy)
    assert np.allclose(r_pi, [0.25, 0.0]) and np.allclose(p_pi, [[0.25, 0.75], [0.5, 0.5]])


@pytest.mark.parametrize(("rewards", "transitions", "gamma", "match"), [
    ([0.0, 1.0], [[0.5, 0.6], [0.0, 1.0]], 0.9, "row-stochastic"),
    ([0.0, 1.0], [[1.0, 0.0]], 0.9, "row-stochastic"),
    ([0.0, 1.0], np.eye(2), 1.0, "discount"),
])
def test_bad_input_is_refused(rewards, transitions, gamma, match) -> None:
    with pytest.raises(ValueError, match=match):
        bisimulation_metric(np.array(rewards), np.array(transitions), gamma)
