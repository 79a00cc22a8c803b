"""When a comparison row's test counts: once, at the trials per arm it planned before its trials ran.

Trials arrive over sessions, and the claims table is regenerated at each count. Reading a verdict at
every count from the protocol's minimum up, and keeping the first that rejects, is optional stopping:
with identical arms looked at at every count from 5 to 10 trials per arm, a false "reproduced" comes
about twice as often as the alpha / 2 one look allows (0.053 against 0.025 in tests/test_verdict_looks.py;
Armitage, McPherson and Rowe 1969 on repeated significance tests). So a row is judged on each arm's
seeds 0 to ``planned_n`` - 1 (``claims.yaml``, fixed before they ran), and a
count between the minimum and the planned n is an interim look, shown but not a verdict. A plan of n
names seeds 0 to n - 1: trials an arm holds beyond them (another row planned more) never enter the row.

Pure functions; docs/verdicts.md says why.
"""
from __future__ import annotations

import math

import numpy as np

TOO_FEW_LOOK, INTERIM_LOOK, FINAL_LOOK = "too few", "interim", "final"


def look(n_a: int, n_b: int, planned_n: int | None, min_n: int) -> str:
    """Which look ``n_a`` + ``n_b`` finished trials give a row: :data:`TOO_FEW_LOOK` below ``min_n``
    in an arm, :data:`INTERIM_LOOK` below the row's ``planned_n`` (None: no plan, so the minimum
    is the plan), :data:`FINAL_LOOK` at or past it. claims.yaml never plans below ``min_n``
    (``claim_settings`` refuses it)."""
    if min(n_a, n_b) < min_n:
        return TOO_FEW_LOOK
    return INTERIM_LOOK if min(n_a, n_b) < (planned_n or min_n) else FINAL_LOOK


def least_rejecting_n(level: float) -> int:
    """The fewest trials per arm (equal arms) at which the protocol's p can reach ``level``: with
    every split of the pooled trials enumerated, the permutation p is at least 2 / C(2n, n) (the
    observed split and its mirror), and the protocol reads the larger of it and the t-distribution
    p. At 5 + 5 that floor is 0.0079, so a row Holm-corrected over 16 can never reject: it needs 6."""
    n = 2
    while 2 / math.comb(2 * n, n) > level:
        n += 1
    return n


def planned_seeds(mask: np.ndarray, seeds: np.ndarray, keep: int | None) -> np.ndarray:
    """``mask`` ``(n,)`` (the trials that may enter, with seeds ``seeds`` ``(n,)``) cut to seeds 0 to
    ``keep`` - 1, the trials a plan of ``keep`` per arm names; None keeps all. A plan's trials are
    named by seed, not by the order they finish in, so a later seed finishing first never enters in
    place of an earlier one."""
    mask = np.asarray(mask, dtype=bool)
    return mask if keep is None else mask & (np.asarray(seeds) < keep)
