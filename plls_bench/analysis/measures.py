"""Numbers that make the paper's qualitative claims about V_a's latent space checkable.

Each function is pure numpy/scipy on arrays; :mod:`plls_bench.analysis.studies` names them in
``metrics/study.json``. Shapes: N points, A action dims, D latent dims.
"""
from __future__ import annotations

import numpy as np
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
    """Held-out accuracy of Fisher's linear discriminant separating ``labels`` (bool ``(N,)``)
    from ``points`` ``(N, D)``: fitted on the even-indexed points and scored on the odd ones,
    then the other way round, averaged. 1: a hyperplane separates the two classes, also on
    points it was not fitted to; 0.5: no better than chance."""
    points, labels = _rows(points), np.asarray(labels, dtype=bool)
    folds = np.arange(len(points)) % 2 == 0
    scores = []
    for fit in (folds, ~folds):
        w, threshold = _fisher(points[fit], labels[fit])
        predicted = points[~fit] @ w > threshold
        scores.append(float(np.mean(predicted == labels[~fit])))
    return float(np.mean(scores))


def _fisher(points: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, float]:
    """Direction ``w`` ``(D,)`` and threshold (midpoint of the projected class means) of
    Fisher's discriminant; a small ridge keeps collapsed latent dims from making it singular."""
    if labels.all() or not labels.any():
        raise ValueError("linear_separability needs points of both classes in each fold")
    m1, m0 = points[labels].mean(axis=0), points[~labels].mean(axis=0)
    centred = np.concatenate([points[labels] - m1, points[~labels] - m0])
    within = centred.T @ centred / len(points)
    ridge = 1e-6 * (np.trace(within) / len(within) + 1e-12)
    w = np.linalg.solve(within + ridge * np.eye(len(within)), m1 - m0)
    return w, float((m1 + m0) @ w / 2)


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
