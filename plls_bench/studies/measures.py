"""Numbers that make the paper's qualitative claims about V_a's latent space checkable.

Each function is pure numpy/scipy on arrays; :mod:`plls_bench.studies.latent_space` names them in
``metrics/study.json``. Shapes: N points, A action dims, D latent dims.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import linprog
from scipy.spatial.distance import pdist, squareform
from scipy.stats import spearmanr


def distance_rank_correlation(actions: np.ndarray, latents: np.ndarray) -> float:
    """Spearman correlation between the N(N-1)/2 pairwise distances of ``actions`` ``(N, A)``
    and of their ``latents`` ``(N, D)`` (Euclidean). 1: the latent space orders every pair of
    actions by how far apart they are, as the action space does; 0: no relation (a random map)."""
    rho = spearmanr(pdist(_rows(actions)), pdist(_rows(latents))).statistic
    return float(rho)


def knn_overlap(actions: np.ndarray, latents: np.ndarray, k: int) -> float:
    """Mean fraction of each point's ``k`` nearest neighbours in action space that are also among
    its ``k`` nearest in latent space. 1: neighbourhoods preserved; a random map scores about
    ``k / (N - 1)``."""
    near_a, near_e = (_neighbours(squareform(pdist(_rows(x))), k) for x in (actions, latents))
    shared = [len(np.intersect1d(a, e, assume_unique=True)) for a, e in zip(near_a, near_e)]
    return float(np.mean(shared) / k)


def _neighbours(distances: np.ndarray, k: int) -> np.ndarray:
    """Indices ``(N, k)`` of each row's k nearest other points (ties broken by index)."""
    np.fill_diagonal(distances, np.inf)
    return np.argsort(distances, axis=1, kind="stable")[:, :k]


def linear_separability(points: np.ndarray, labels: np.ndarray) -> float:
    """Share of ``points`` ``(N, D)`` on their own ``labels``' (bool ``(N,)``) side of the linear
    SVM fitted to all of them (hinge loss, solved exactly as a linear programme). 1.0 exactly when
    a hyperplane separates the two classes; about 0.5 (a little more, from fitting) for classes
    that overlap completely."""
    x, y = _rows(points), np.where(np.asarray(labels, dtype=bool), 1.0, -1.0)
    if (y > 0).all() or (y < 0).all():
        raise ValueError("linear_separability needs points of both classes")
    n, d = x.shape
    # Variables [w (D), b, slack (N)]: minimise sum(slack) s.t. y_i (w . x_i + b) >= 1 - slack_i.
    cost = np.concatenate([np.zeros(d + 1), np.ones(n)])
    a_ub = np.hstack([-y[:, None] * x, -y[:, None], -np.eye(n)])
    bounds = [(None, None)] * (d + 1) + [(0, None)] * n
    result = linprog(cost, A_ub=a_ub, b_ub=-np.ones(n), bounds=bounds, method="highs")
    if not result.success:
        raise RuntimeError(f"linear_separability: the SVM programme failed ({result.message})")
    w, b = result.x[:d], result.x[d]
    return float(np.mean(y * (x @ w + b) > 0))


def deviation_stats(raw: np.ndarray, decoded: np.ndarray) -> dict[str, float]:
    """How decoded actions deviate from the raw ones they encode; ``decoded`` has the shape of
    ``raw`` or extra trailing sample axes (``(K, S)`` for ``(K,)``). Keys: ``mean_abs_action_error``
    (mean |a_hat - a|), ``std_abs_action_error`` (its spread), ``mean_action_deviation`` and
    ``std_action_deviation`` (signed a_hat - a: bias and spread), ``mse``, ``max_abs_action_error``,
    ``sign_agreement`` (fraction of a_hat pushing the same way as a)."""
    decoded = np.asarray(decoded, dtype=np.float64)
    raw = np.asarray(raw, dtype=np.float64)
    raw = raw.reshape(raw.shape + (1,) * (decoded.ndim - raw.ndim))  # broadcast over samples
    deviation = decoded - raw
    same_sign = np.sign(decoded) == np.sign(raw)
    return {"mean_abs_action_error": float(np.abs(deviation).mean()),
            "std_abs_action_error": float(np.abs(deviation).std()),
            "mean_action_deviation": float(deviation.mean()), "std_action_deviation": float(deviation.std()),
            "mse": float((deviation ** 2).mean()), "max_abs_action_error": float(np.abs(deviation).max()),
            "sign_agreement": float(same_sign.mean())}


def state_error(a: np.ndarray, b: np.ndarray, scale: np.ndarray) -> float:
    """Mean Euclidean distance between states ``a`` and ``b`` ``(..., 2)`` after dividing each
    coordinate by ``scale`` ``(2,)`` (MountainCar's x and x_dot spans, so both count alike)."""
    return float(np.linalg.norm((np.asarray(a) - np.asarray(b)) / scale, axis=-1).mean())


def _rows(x: np.ndarray) -> np.ndarray:
    """``(N,)`` or ``(N, D)`` as ``(N, D)`` float64."""
    x = np.asarray(x, dtype=np.float64)
    return x[:, None] if x.ndim == 1 else x
