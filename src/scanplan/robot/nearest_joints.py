"""The joints a controller takes for a pose: the IK's solutions shifted by whole turns into
the joint limits (`fit_limits`), whether any lies within them (`solvable`), the in-limit
solution nearest the joints before (`nearest_solution`), and a branch followed that way
over many poses at once (`follow`): what `reach.check_reach` steps a path with.
"""

from __future__ import annotations

import numpy as np

from scanplan.robot.base import wrap

TWO_PI = 2 * np.pi


def fit_limits(q: np.ndarray, limits: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(q shifted by whole turns into the limits where it can be, (…,) all joints inside).
    Ranges wider than ±180° (KUKA A6 ±350°, UR ±360°) make several turns legal: the one
    closest to the given q is kept."""
    lo, hi = limits[:, 0], limits[:, 1]
    # A turn down where above the range, up where below (never both: lo < hi), by
    # arithmetic on the tests: the same values as choosing with `np.where`, at a third of
    # its cost.
    for _ in range(2):
        q = q - TWO_PI * (q > hi) + TWO_PI * (q < lo)
    return q, reduce_last_axis((q >= lo - 1e-12) & (q <= hi + 1e-12), np.logical_and)


def solvable(solutions: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """(…,) whether any of each pose's IK solutions (…, 8, 6) lies within the limits, shifted
    by whole turns: where `reach.check_reach` finds joints for it, whichever branch it
    follows (the nearest in-limit solution exists exactly then), in one array operation."""
    q, inside = fit_limits(solutions, limits)
    return (inside & ~np.isnan(q).any(axis=-1)).any(axis=-1)


def limit_margin(q: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """(…,) rad to the nearest joint limit (negative beyond it)."""
    return reduce_last_axis(np.minimum(q - limits[:, 0], limits[:, 1] - q), np.minimum)


def reduce_last_axis(per_joint: np.ndarray, combine: np.ufunc) -> np.ndarray:
    """`combine` reduced over the last axis (joints, singularity terms) column by column:
    numpy's reduction over a short last axis costs twice to ten times as much, and the
    placement search reduces millions of solutions."""
    out = combine(per_joint[..., 0], per_joint[..., 1])
    for j in range(2, per_joint.shape[-1]):
        combine(out, per_joint[..., j], out=out)
    return np.asarray(out)


def _candidates(
    solutions: np.ndarray, limits: np.ndarray, prev: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(m, 8, 6) each pose's solutions turned the way nearest `prev` (m, 6) and shifted into
    the limits where they can be; (m, 8) their squared distance to `prev`, inf where there
    is no solution within the limits."""
    cand, inside = fit_limits(prev[:, None] + wrap(solutions - prev[:, None]), limits)
    inside &= ~np.isnan(cand).any(axis=-1)
    dist = np.where(inside, ((cand - prev[:, None]) ** 2).sum(axis=-1), np.inf)
    return cand, dist


def nearest_solution(
    solutions: np.ndarray, limits: np.ndarray, prev: np.ndarray
) -> tuple[int, np.ndarray] | None:
    """(branch, joints) of the one pose's (1, 8, 6) in-limit solution nearest `prev` (1, 6),
    as a controller moving linearly takes it; None if it has none within the limits."""
    cand, dist = _candidates(solutions, limits, prev)
    branch = int(np.argmin(dist[0]))
    return None if not np.isfinite(dist[0, branch]) else (branch, cand[0, branch])


def next_within(
    solutions: np.ndarray, limits: np.ndarray, prev: np.ndarray | None, lo: int, hi: int
) -> int:
    """The first pose from `lo` on, before `hi`, with an in-limit solution from `prev` (None:
    any in-limit solution; `hi` if none): the poses `check_reach` would step one by one,
    finding none, while its joints stay at `prev`. Looked for in growing windows, so a short
    gap costs a short look."""
    size = 8
    while lo < hi:
        top = min(hi, lo + size)
        if prev is None:
            found = solvable(solutions[lo:top], limits)
        else:
            _, dist = _candidates(solutions[lo:top], limits, np.broadcast_to(prev, (top - lo, 6)))
            found = np.isfinite(dist).any(axis=1)
        if found.any():
            return lo + int(np.argmax(found))
        lo, size = top, size * 8
    return hi


def follow(solutions: np.ndarray, limits: np.ndarray, prev: np.ndarray, branch: int) -> np.ndarray:
    """(t, 6) the joints of the first t poses of `solutions` (m, 8, 6) while taking, pose by
    pose, the in-limit solution nearest the previous joints (`nearest_solution`) stays on
    `branch` from `prev`: each pose checked against the branch's path unwrapped from `prev`
    at once, so a pass or a joint move's poses cost a few array operations instead of a
    Python step a pose. t stops at the first pose where the nearest is another branch, or
    none (the caller steps it alone)."""
    if not len(solutions):
        return np.zeros((0, 6))
    along = solutions[:, branch]
    path = prev + np.cumsum(wrap(np.diff(np.r_[prev[None], along], axis=0)), axis=0)
    before = np.r_[prev[None], path[:-1]]
    cand, dist = _candidates(solutions, limits, before)
    held = (np.argmin(dist, axis=1) == branch) & np.isfinite(dist[:, branch])
    # Shifted by a turn into the limits, or off the unwrapped path: stepped alone.
    held &= (np.abs(cand[:, branch] - path) < 1e-9).all(axis=1)
    t = len(held) if held.all() else int(np.argmin(held))
    return cand[:t, branch]


__all__ = [
    "fit_limits",
    "follow",
    "limit_margin",
    "nearest_solution",
    "next_within",
    "reduce_last_axis",
    "solvable",
]
