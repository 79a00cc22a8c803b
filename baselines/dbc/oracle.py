"""Exact on-policy bisimulation metric of a small finite MDP (the test oracle for DBC's encoder).

For a policy pi with per-state reward ``r`` ``(n,)`` and transition matrix ``P`` ``(n, n)``, the
on-policy bisimulation metric (Castro 2020; Zhang et al. 2021, Def. 2) is the unique fixed point of

    F(d)(s, t) = |r_s - r_t| + gamma * W_1(d)(P_s, P_t),

a gamma-contraction in the sup norm. W_1(d) is the Kantorovich optimal transport cost between the
next-state distributions under ground cost d; each one is a linear program, solved here with cvxpy
(all pairs of an iteration in one LP, since their objectives are independent). Iterating F from
d = 0 converges geometrically; iteration stops when the a-posteriori bound
``gamma / (1 - gamma) * ||d_{k+1} - d_k||_inf`` on the distance to the fixed point is below ``tol``.
"""
from __future__ import annotations

import itertools

import cvxpy as cp
import numpy as np


def _solver() -> str | None:
    return "HIGHS" if "HIGHS" in cp.installed_solvers() else None  # exact simplex/IPM for LPs


def wasserstein1(p: np.ndarray, q: np.ndarray, cost: np.ndarray) -> float:
    """W_1 between distributions ``p``, ``q`` ``(n,)`` under ground cost ``cost`` ``(n, n)``."""
    coupling = cp.Variable(cost.shape, nonneg=True)
    constraints = [cp.sum(coupling, axis=1) == p, cp.sum(coupling, axis=0) == q]
    problem = cp.Problem(cp.Minimize(cp.sum(cp.multiply(coupling, cost))), constraints)
    problem.solve(solver=_solver())
    _check(problem)
    return float(problem.value)


class _PairwiseW1:
    """One parametrised LP giving W_1(d)(P_s, P_t) for every pair s < t; ``d`` is a parameter,
    so cvxpy compiles the problem once and each iteration only re-solves it."""

    def __init__(self, transitions: np.ndarray) -> None:
        n = len(transitions)
        self.pairs = list(itertools.combinations(range(n), 2))
        self.cost = cp.Parameter((n, n), nonneg=True)
        self.couplings = [cp.Variable((n, n), nonneg=True) for _ in self.pairs]
        constraints = []
        for (s, t), coupling in zip(self.pairs, self.couplings):
            constraints += [cp.sum(coupling, axis=1) == transitions[s], cp.sum(coupling, axis=0) == transitions[t]]
        objective = sum(cp.sum(cp.multiply(coupling, self.cost)) for coupling in self.couplings)
        self.problem = cp.Problem(cp.Minimize(objective), constraints)

    def __call__(self, d: np.ndarray) -> np.ndarray:
        """``(n, n)`` symmetric matrix of W_1(d) between the rows of the transition matrix."""
        self.cost.value = np.maximum(d, 0.0)
        self.problem.solve(solver=_solver())
        _check(self.problem)
        w = np.zeros_like(d)
        for (s, t), coupling in zip(self.pairs, self.couplings):
            w[s, t] = w[t, s] = float(np.sum(np.maximum(coupling.value, 0.0) * self.cost.value))
        return w


def bisimulation_metric(rewards: np.ndarray, transitions: np.ndarray, discount: float,
                        tol: float = 1e-7, max_iterations: int = 10_000) -> tuple[np.ndarray, int]:
    """The on-policy bisimulation metric ``(n, n)`` and the number of iterations it took.

    ``rewards`` ``(n,)`` is r^pi(s); ``transitions`` ``(n, n)`` is P^pi(s' | s), rows summing to 1.
    """
    rewards, transitions = np.asarray(rewards, float), np.asarray(transitions, float)
    n = len(rewards)
    if transitions.shape != (n, n) or not np.allclose(transitions.sum(axis=1), 1.0) or (transitions < 0).any():
        raise ValueError(f"transitions must be a ({n}, {n}) row-stochastic matrix")
    if not 0 <= discount < 1:
        raise ValueError(f"discount must be in [0, 1), got {discount}")
    reward_gap = np.abs(rewards[:, None] - rewards[None, :])
    w1 = _PairwiseW1(transitions)
    d = np.zeros((n, n))
    for iteration in range(1, max_iterations + 1):
        new = reward_gap + discount * w1(d)
        change = np.abs(new - d).max()
        d = new
        if discount / (1 - discount) * change <= tol:
            return d, iteration
    raise RuntimeError(f"bisimulation metric did not converge to {tol} in {max_iterations} iterations")


def on_policy(rewards: np.ndarray, transitions: np.ndarray, policy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """r^pi ``(n,)`` and P^pi ``(n, n)`` from r(s, a) ``(n, A)``, P(s' | s, a) ``(n, A, n)`` and
    pi(a | s) ``(n, A)``."""
    return (policy * rewards).sum(axis=1), np.einsum("sa,sat->st", policy, transitions)


def _check(problem: cp.Problem) -> None:
    if problem.status != cp.OPTIMAL:
        raise RuntimeError(f"transport LP not solved to optimality: status {problem.status}")
