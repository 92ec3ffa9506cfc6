"""Thinning a run of planned poses to the fewest linear-move targets that keep the flown path
within a chord tolerance (mm) and an angle tolerance (rad) of every planned pose.

A linear move interpolates position linearly and orientation by slerp with one parameter, so
each dropped pose is judged against the move's pose at its own parameter: its arc-length
share of the planned run between the two kept targets (the sensor flies at constant speed).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def segment_errors(
    poses: np.ndarray, i: int, j: int, turns: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(position error mm, angle error rad) of poses i+1..j-1 of (n, 4, 4) `poses` against
    the linear move from pose i to pose j, each at its own arc-length parameter. turns:
    the poses' orientations as quaternions (`quaternions`), if the caller has them."""
    q = quaternions(poses[i : j + 1]) if turns is None else turns[i : j + 1]
    u = interp_params(poses[i : j + 1, :3, 3])[1:-1]
    inner = slice(i + 1, j)
    flown = poses[i, :3, 3] + np.outer(u, poses[j, :3, 3] - poses[i, :3, 3])
    pos_err = np.linalg.norm(poses[inner, :3, 3] - flown, axis=1)
    off = _product(_conjugate(slerp(q[0], q[-1], u)), q[1:-1])  # flown to planned
    ang_err = 2.0 * np.arctan2(np.linalg.norm(off[:, :3], axis=1), np.abs(off[:, 3]))
    return pos_err, ang_err


def linear_move(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(k, 4, 4) the poses at parameters `u` (k,) in [0, 1] of a controller's linear move
    from pose a to pose b: position linearly, orientation by slerp, with one parameter."""
    q = quaternions(np.stack([a, b]))
    out = np.broadcast_to(np.eye(4), (len(u), 4, 4)).copy()
    out[:, :3, :3] = Rotation.from_quat(slerp(q[0], q[1], np.asarray(u))).as_matrix()
    out[:, :3, 3] = a[:3, 3] + np.outer(u, b[:3, 3] - a[:3, 3])
    return out


def quaternions(poses: np.ndarray) -> np.ndarray:
    """(n, 4) the orientations of (n, 4, 4) poses as unit quaternions (x, y, z, w)."""
    return Rotation.from_matrix(poses[:, :3, :3]).as_quat()


def slerp(q0: np.ndarray, q1: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(k, 4) the orientations at parameters `u` (k,) of the shortest turn at constant rate
    from quaternion q0 to q1 (x, y, z, w): how a controller turns the tool in a linear move."""
    turn = _product(_conjugate(q0)[None], q1[None])[0]
    turn = turn if turn[3] >= 0 else -turn  # the shorter way round
    sin_half = float(np.linalg.norm(turn[:3]))
    angle = 2.0 * np.arctan2(sin_half, turn[3])
    axis = turn[:3] / sin_half if sin_half > 1e-15 else np.zeros(3)
    half = 0.5 * angle * np.asarray(u, dtype=np.float64)
    step = np.concatenate([np.sin(half)[:, None] * axis, np.cos(half)[:, None]], axis=1)
    return _product(np.broadcast_to(q0, step.shape), step)


def _conjugate(q: np.ndarray) -> np.ndarray:
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def _product(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(k, 4) the Hamilton products p q of quaternions (x, y, z, w), row by row."""
    px, py, pz, pw = p.T
    qx, qy, qz, qw = q.T
    return np.stack(
        [
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy + py * qw + pz * qx - px * qz,
            pw * qz + pz * qw + px * qy - py * qx,
            pw * qw - px * qx - py * qy - pz * qz,
        ],
        axis=1,
    )


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
    turns = quaternions(poses)
    stack = [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        pos_err, ang_err = segment_errors(poses, i, j, turns)
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
