"""Thinning a run of planned poses to the fewest linear-move targets that keep the flown path
within a chord tolerance (mm) and an angle tolerance (rad) of every planned pose.

A linear move interpolates position linearly and orientation by slerp with one parameter, so
each dropped pose is judged against the move's pose at its own parameter: its arc-length
share of the planned run between the two kept targets (the sensor flies at constant speed).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def segment_errors(poses: np.ndarray, i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
    """(position error mm, angle error rad) of poses i+1..j-1 of (n, 4, 4) `poses` against
    the linear move from pose i to pose j, each at its own arc-length parameter."""
    u = interp_params(poses[i : j + 1, :3, 3])[1:-1]
    inner = slice(i + 1, j)
    flown = linear_move(poses[i], poses[j], u)
    pos_err = np.linalg.norm(poses[inner, :3, 3] - flown[:, :3, 3], axis=1)
    turned = Rotation.from_matrix(flown[:, :3, :3]).inv()
    ang_err = (turned * Rotation.from_matrix(poses[inner, :3, :3])).magnitude()
    return pos_err, ang_err


def linear_move(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(k, 4, 4) the poses at parameters `u` (k,) in [0, 1] of a controller's linear move
    from pose a to pose b: position linearly, orientation by slerp, with one parameter."""
    r0 = Rotation.from_matrix(a[:3, :3])
    turn = (r0.inv() * Rotation.from_matrix(b[:3, :3])).as_rotvec()
    out = np.broadcast_to(np.eye(4), (len(u), 4, 4)).copy()
    out[:, :3, :3] = (r0 * Rotation.from_rotvec(np.outer(u, turn))).as_matrix()
    out[:, :3, 3] = a[:3, 3] + np.outer(u, b[:3, 3] - a[:3, 3])
    return out


def interp_params(p: np.ndarray) -> np.ndarray:
    """(m,) arc-length share in [0, 1] of each of the (m, 3) positions along their polyline;
    the index share where the run does not move (a turn on the spot)."""
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    total = step.sum()
    if total <= 1e-9:
        return np.linspace(0.0, 1.0, len(p))
    return np.r_[0.0, np.cumsum(step)] / total


def thin_run(poses: np.ndarray, chord_tol_mm: float, angle_tol_rad: float) -> np.ndarray:
    """Indices (ascending, first and last always) of the targets to keep of the (n, 4, 4)
    run `poses`, Douglas–Peucker style: split a move at its worst pose (the larger of the
    position and angle errors, each over its tolerance) until every pose is within both."""
    n = len(poses)
    if n <= 2:
        return np.arange(n)
    keep = np.zeros(n, dtype=bool)
    keep[[0, n - 1]] = True
    stack = [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        pos_err, ang_err = segment_errors(poses, i, j)
        worst = np.maximum(pos_err / chord_tol_mm, ang_err / angle_tol_rad)
        k = int(np.argmax(worst))
        if worst[k] > 1.0:
            m = i + 1 + k
            keep[m] = True
            stack += [(i, m), (m, j)]
    return np.flatnonzero(keep)


def thin(
    poses: np.ndarray, breaks: np.ndarray, chord_tol_mm: float, angle_tol_rad: float
) -> np.ndarray:
    """Indices of the targets to keep of (n, 4, 4) `poses`, thinned run by run: a run ends at
    every pose where `breaks` (n,) bool is set (pass starts and ends, where the motion
    changes), and those poses are always kept."""
    n = len(poses)
    cuts = np.unique(np.r_[0, np.flatnonzero(breaks), n - 1])
    kept = [cuts]
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        if b - a >= 2:
            kept.append(a + thin_run(poses[a : b + 1], chord_tol_mm, angle_tol_rad))
    return np.unique(np.concatenate(kept))
