"""The exact maximum cover: which k of several sets cover the most samples together, as a
mixed-integer program solved by HiGHS (`scipy.optimize.milp`). `view_choice.choose_views`
picks views greedily and records how far that is from this (`benchmarks/compare_views.py`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.optimize import Bounds, LinearConstraint, milp
from scipy.sparse import coo_matrix


def max_cover(
    sets: Sequence[np.ndarray], k: int, time_limit_s: float = 30.0
) -> tuple[list[int], float]:
    """The indices of at most `k` of `sets` ((n,) bool each, over the same n samples) whose
    union is largest, and that union's share of the n samples. Samples covered by the same
    sets are one variable weighted by their count, so the program has one variable per
    set and per distinct pattern of membership. Raises ValueError if HiGHS finds no
    solution within `time_limit_s`."""
    if k < 1 or not sets:
        return [], 0.0
    member = np.stack([np.asarray(s, bool) for s in sets])  # (m, n)
    m, n = member.shape
    covered_by_any = member.any(axis=0)
    patterns, weight = np.unique(
        np.packbits(member[:, covered_by_any], axis=0).T, axis=0, return_counts=True
    )
    which = np.unpackbits(patterns, axis=1, count=m).astype(bool)  # (p, m)
    p = len(patterns)
    # Variables: x (m sets), then y (p patterns); maximize Σ weight·y.
    c = np.concatenate([np.zeros(m), -weight.astype(np.float64)])
    # y_j − Σ_{i covers j} x_i ≤ 0
    rows, cols = np.nonzero(which)
    a = coo_matrix(
        (
            np.concatenate([np.ones(p), -np.ones(len(rows))]),
            (np.concatenate([np.arange(p), rows]), np.concatenate([m + np.arange(p), cols])),
        ),
        shape=(p + 1, m + p),
    ).tolil()
    a[p, :m] = 1.0  # Σ x ≤ k
    upper = np.concatenate([np.zeros(p), [float(k)]])
    result = milp(
        c,
        constraints=LinearConstraint(a.tocsr(), -np.inf, upper),
        integrality=np.concatenate([np.ones(m), np.zeros(p)]),
        bounds=Bounds(0, 1),
        options={"time_limit": time_limit_s},
    )
    if result.x is None:
        raise ValueError(f"no cover found within {time_limit_s:g} s: {result.message}")
    chosen = [int(i) for i in np.flatnonzero(result.x[:m] > 0.5)]
    union = member[chosen].any(axis=0) if chosen else np.zeros(n, bool)
    return chosen, float(union.mean())
