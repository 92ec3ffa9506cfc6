"""Which poses `place` scores placements on, and what each counts for: `sample_poses`, the
coarse samples; `pose_weights`, each pose's worth from the surface its view holds in spec
(`view_worths`); `weighted_sample`, a sample with every view in it and the worths of the
poses each sampled one stands for.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from scanplan.core.plan import view_records
from scanplan.core.trajectory import Trajectory

# A move's weight, of the mean scanning pose's: a move given up is flown as a joint move, so
# moves only break ties between placements that keep the same scanning.
MOVE_WEIGHT = 1e-3


def sample_poses(traj: Trajectory, m: int) -> np.ndarray:
    """Indices of at most 2m poses: m evenly spaced, and the first and last poses of the
    passes and moves (m of them evenly spaced among those, when there are more: a plan of
    many views has hundreds, which made the search's sample ten times its `m`)."""
    n = len(traj)
    s, w = traj.scanning, traj.swath
    edge = np.r_[True, (s[1:] != s[:-1]) | (w[1:] != w[:-1])]
    ends = np.flatnonzero(edge | np.r_[edge[1:], True])
    if len(ends) > m:
        ends = ends[np.linspace(0, len(ends) - 1, m).round().astype(int)]
    even = np.linspace(0, n - 1, min(m, n)).round().astype(int)
    return np.union1d(ends, even)


def view_worths(in_spec: Sequence[np.ndarray]) -> np.ndarray:
    """(v,) each view's share of the surface, from its in-spec set on common samples: each
    sample it holds counts 1 / the number of views holding it, so the worths sum to the
    share the views hold together, and a view holding only what others hold is worth
    little however many poses it has."""
    held = np.stack([np.asarray(s, bool) for s in in_spec])
    if held.shape[1] == 0:
        return np.zeros(len(held))
    holders = held.sum(axis=0)
    return (held / np.maximum(holders, 1)).sum(axis=1) / held.shape[1]


def pose_weights(traj: Trajectory, worths: np.ndarray) -> np.ndarray:
    """(n,) each pose's weight: view k of `traj` (`meta["views"]`) worth `worths[k]`, spread
    evenly over its scanning poses; the moves, and the poses of a view worth nothing,
    `MOVE_WEIGHT` of the mean scanning pose's."""
    views = view_records(traj)
    if len(views) != len(worths):
        raise ValueError(f"{len(worths)} view worths for a plan of {len(views)} views")
    weights = np.zeros(len(traj))
    for view, worth in zip(views, worths, strict=True):
        mine = view.holds(traj.swath) & traj.scanning
        if mine.any():
            weights[mine] = worth / mine.sum()
    scanned = weights[traj.scanning]
    mean = float(scanned.mean()) if len(scanned) and scanned.sum() > 0 else 1.0
    return np.maximum(weights, MOVE_WEIGHT * mean)


def checked_weights(weights: np.ndarray | None, n: int) -> np.ndarray | None:
    """`weights` as (n,) float, or a ValueError saying what is wrong with them."""
    if weights is None:
        return None
    w = np.asarray(weights, dtype=np.float64)
    if w.shape != (n,) or not np.isfinite(w).all() or (w < 0).any() or w.sum() <= 0:
        raise ValueError(f"weights must be {n} finite values >= 0, not all 0")
    return w


def weighted_sample(
    traj: Trajectory, weights: np.ndarray | None, sample: np.ndarray, per_view: int
) -> tuple[np.ndarray, np.ndarray | None]:
    """`sample` (sorted indices) as the weighted search scores on: with `per_view` scanning
    poses, evenly spaced inside it, of every recorded view it has none of (the coarse one,
    94 poses, missed 77 of the quadrotor's 116 views, a quarter of their worth: a view
    missed counts for nothing), and each sampled pose weighted by the poses of its view it
    stands for (`_stood_for`), so a view sampled densely counts no more than its worth.
    Unweighted (None): the sample as it is."""
    if weights is None:
        return sample, None
    picks = [np.asarray(sample, int)]
    for view in view_records(traj):
        mine = np.flatnonzero(view.holds(traj.swath) & traj.scanning)
        if len(mine) and not np.isin(mine, sample).any():
            at = np.linspace(0, len(mine) - 1, per_view + 2)[1:-1].round().astype(int)
            picks.append(mine[at])
    sample = np.unique(np.concatenate(picks))
    return sample, _stood_for(traj, weights, sample)


def _stood_for(traj: Trajectory, weights: np.ndarray, sample: np.ndarray) -> np.ndarray:
    """(m,) the weight of the poses each of `sample` stands for: those of its own view's
    scanning (or moves, or of the poses no view holds) nearer it than the others sampled
    there. Within the view: a view's one pose in the sample would otherwise take half the
    way to its neighbours in the sample, hundreds of another view's poses."""
    group = np.full(len(traj), -1)
    for k, view in enumerate(view_records(traj)):
        mine = view.holds(traj.swath)
        group[mine] = 2 * k + traj.scanning[mine]
    out = np.zeros(len(sample))
    sampled_group = group[sample]
    for g in np.unique(sampled_group):
        at = np.flatnonzero(sampled_group == g)
        poses = np.flatnonzero(group == g)
        cell = np.searchsorted((sample[at][1:] + sample[at][:-1]) / 2, poses)
        out[at] = np.bincount(cell, weights[poses], len(at))
    return out


__all__ = [
    "MOVE_WEIGHT",
    "checked_weights",
    "pose_weights",
    "sample_poses",
    "view_worths",
    "weighted_sample",
]
