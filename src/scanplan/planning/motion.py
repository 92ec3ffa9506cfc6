"""Collision-free moves between scanning poses (SPEC §3b): lift along the view axis, cross at
a height where the sensor body clears the part by the clearance, descend to the next pass.

Segments are sampled densely (`step_mm`) so the check sees every place the body passes; the
crossing height starts at the higher end and rises until every sample is clear.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from scanplan.core.quantities import UP
from scanplan.core.trajectory import MOVE_STEP_MM
from scanplan.world.collision import CellChecker, CollisionChecker


def _line(a: np.ndarray, b: np.ndarray, step_mm: float) -> np.ndarray:
    """Points from a (excluded) to b (included), at most step_mm apart. (k, 3), k >= 0."""
    length = float(np.linalg.norm(b - a))
    if length < 1e-9:
        return np.zeros((0, 3))
    k = max(1, math.ceil(length / step_mm - 1e-9))
    t = np.arange(1, k + 1)[:, None] / k
    return a + t * (b - a)


def _poses(rotation: np.ndarray, positions: np.ndarray) -> np.ndarray:
    poses = np.tile(np.eye(4), (len(positions), 1, 1))
    poses[:, :3, :3] = rotation
    poses[:, :3, 3] = positions
    return poses


def straight_move(
    start: np.ndarray, end_mm: np.ndarray, step_mm: float = MOVE_STEP_MM
) -> np.ndarray:
    """Poses (k, 4, 4) from `start` (excluded) straight to the position `end_mm` (included),
    orientation kept, at most step_mm apart: every place the body passes gets checked."""
    return _poses(start[:3, :3], _line(start[:3, 3], np.asarray(end_mm, float), step_mm))


def lift_cross_descend(
    start: np.ndarray,
    end: np.ndarray,
    height_mm: float,
    up: np.ndarray = UP,
    step_mm: float = MOVE_STEP_MM,
    body_radius_mm: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The poses strictly between `start` and `end` (4x4): straight up along `up` to
    `height_mm`, across at that height (the orientation slerped from start's to end's, no
    body point moving more than step_mm between samples, `body_radius_mm` the body's reach),
    straight down. Returns the poses (k, 4, 4) and (k,) bool, True on the crossing."""
    p0, p1 = start[:3, 3], end[:3, 3]
    q0 = p0 + (height_mm - float(p0 @ up)) * up
    q1 = p1 + (height_mm - float(p1 @ up)) * up
    lift = _line(p0, q0, step_mm)
    descend = _line(q1, p1, step_mm)[:-1]  # without `end` itself
    rotations = Rotation.from_matrix(np.stack([start[:3, :3], end[:3, :3]]))
    angle = float((rotations[0].inv() * rotations[1]).magnitude())
    reach = max(float(np.linalg.norm(q1 - q0)), angle * body_radius_mm)
    k = max(1, math.ceil(reach / step_mm - 1e-9))
    t = np.arange(1, k + 1) / k
    if len(descend) == 0 and np.allclose(q1, p1):
        t = t[:-1]  # no descent: the crossing's last sample would be `end`
    cross_rot = Slerp([0.0, 1.0], rotations)(t).as_matrix()
    cross = _poses(np.eye(3), q0 + t[:, None] * (q1 - q0))
    cross[:, :3, :3] = cross_rot
    poses = np.concatenate([_poses(start[:3, :3], lift), cross, _poses(end[:3, :3], descend)])
    on_cross = np.zeros(len(poses), bool)
    on_cross[len(lift) : len(lift) + len(cross)] = True
    return poses, on_cross


def plan_transition(
    checker: CollisionChecker | CellChecker,
    start: np.ndarray,
    end: np.ndarray,
    clearance_mm: float,
    up: np.ndarray = UP,
    step_mm: float = MOVE_STEP_MM,
    raise_step_mm: float = MOVE_STEP_MM,
) -> np.ndarray:
    """Non-scanning poses (k, 4, 4) from `start` to `end` (both excluded) that keep the
    sensor body at least `clearance_mm` from the part.

    The crossing starts at the higher end's height and rises (by the largest shortfall of
    clearance, at least `raise_step_mm`) until every sample is clear; it is bounded by the
    height where the whole body is above the part's top by the clearance. Lift and descent
    that collide cannot be fixed by a higher crossing. With step_mm <= 2 x clearance, no
    point of the body passes closer to the part than clearance - step/2 between samples of a
    straight segment. Raises ValueError if no crossing up to that bound is clear.
    """
    up = np.asarray(up, dtype=np.float64) / np.linalg.norm(up)
    radius = checker.body_radius_mm
    top = float((checker.vertices @ up).max())
    # How far below the sensor origin the body reaches at the two ends; a turn between them
    # may swing it as far as its radius.
    below = max(
        float(p[:3, 3] @ up - (checker.body_corners_part(p)[0] @ up).min()) for p in (start, end)
    )
    ceiling = top + clearance_mm + (radius if _turns(start, end) else below)
    height = max(float(start[:3, 3] @ up), float(end[:3, 3] @ up))
    while True:
        poses, on_cross = lift_cross_descend(start, end, height, up, step_mm, radius)
        report = checker.check(poses, clearance_mm)
        bad = report.colliding
        if not bad.any():
            return poses
        if (bad & ~on_cross).any():
            where = poses[np.flatnonzero(bad & ~on_cross)[0], :3, 3]
            raise ValueError(
                f"no collision-free transition: the sensor body comes within {clearance_mm:g} mm "
                f"of the part while lifting or descending at {np.round(where, 1).tolist()} mm"
            )
        if height >= ceiling:
            where = poses[np.flatnonzero(bad)[0], :3, 3]
            raise ValueError(
                f"no collision-free transition: crossing at {height:.1f} mm, above the part's "
                f"top, still comes within {clearance_mm:g} mm of it at "
                f"{np.round(where, 1).tolist()} mm"
            )
        shortfall = float(clearance_mm - report.distance_mm[bad].min())
        height = min(ceiling, height + max(raise_step_mm, shortfall))


def _turns(start: np.ndarray, end: np.ndarray) -> bool:
    return not np.allclose(start[:3, :3], end[:3, :3], atol=1e-9)


def view_transition(
    checker: CollisionChecker | CellChecker,
    prev_pose: np.ndarray,
    prev_axis: np.ndarray,
    next_pose: np.ndarray,
    next_axis: np.ndarray,
    centre_mm: np.ndarray,
    radius_mm: float,
    clearance_mm: float,
) -> np.ndarray:
    """Non-scanning poses (k, 4, 4) from the last pose of one view to the first of the next,
    ending on it, clear of the part by `clearance_mm` (`motion.plan_transition`: up, across
    above the part, down). Where going straight up from a pose is not clear (a view under an
    overhang), the move first backs out along the view's axis to the sphere of `radius_mm`
    around the part and comes in the same way. Raises ValueError if neither is clear."""
    try:
        moves = plan_transition(checker, prev_pose, next_pose, clearance_mm)
        return np.concatenate([moves, next_pose[None]])
    except ValueError:
        pass

    def backed_out(pose: np.ndarray, axis: np.ndarray) -> np.ndarray:
        out = pose.copy()
        p = pose[:3, 3] - centre_mm
        b = float(p @ axis)
        c = float(p @ p) - radius_mm**2
        out[:3, 3] = pose[:3, 3] + max(0.0, -b + math.sqrt(max(b * b - c, 0.0))) * axis
        return out

    a, b = backed_out(prev_pose, prev_axis), backed_out(next_pose, next_axis)
    moves = np.concatenate(
        [
            straight_move(prev_pose, a[:3, 3]),
            plan_transition(checker, a, b, clearance_mm),
            straight_move(b, next_pose[:3, 3]),
        ]
    )
    colliding = checker.colliding(moves, clearance_mm)
    if colliding.any():
        where = moves[np.flatnonzero(colliding)[0], :3, 3]
        raise ValueError(
            f"no collision-free move between views: the sensor body comes within "
            f"{clearance_mm:g} mm of the part at {np.round(where, 1).tolist()} mm"
        )
    return moves
