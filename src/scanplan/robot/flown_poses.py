"""Which of a plan's poses an arm flies from a placement: each pose as planned and turned half
a turn about the sensor's beam (reach and limits, the arm's links, the sensor body), and
each pass flown the way that keeps more of it. What `place` ranks placements by and `fit`
and the external axes' choice keep poses by.
"""

from __future__ import annotations

import numpy as np

from scanplan.core.trajectory import Trajectory
from scanplan.robot.base import Robot
from scanplan.robot.links import check_links
from scanplan.robot.nearest_joints import solvable
from scanplan.robot.reach import check_reach
from scanplan.world.capsule_collision import CellObstacles

# Half a turn about the sensor's beam (z_s): the laser line lands where it did, the camera
# looks from the other side, and the wrist gets another way to reach the pose.
HALF_TURN = np.diag([-1.0, -1.0, 1.0, 1.0])


def flyable_poses(
    traj: Trajectory,
    arm: Robot,
    T_base_part: np.ndarray,
    inv_tcp: np.ndarray,
    obstacles: CellObstacles | None,
    index: np.ndarray | None = None,
    sensor_ok: tuple[np.ndarray, np.ndarray] | None = None,
    exact: bool = True,
    choosing: np.ndarray | None = None,
    restarts: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(as planned, turned half a turn about the beam): (m,) bool, the poses `index` (all by
    default) of `traj` the arm reaches within its limits with its links clear, and (the
    body is not symmetric about the beam) the sensor keeping its clearance. sensor_ok: that
    last verdict for both, if known (it does not depend on the placement); without
    `obstacles`, reach and the sensor alone (no link checked). exact=False: the
    links' quick, slightly cautious verdict (`links.check_links`). T_base_part: (4, 4), or
    (len(traj), 4, 4) one per pose (external axes). choosing: (m,) bool, for a caller that
    only chooses per pass the way that keeps more of these poses: a pass whose turned poses
    could not keep more of them than its planned ones keep (on reach and the sensor alone)
    reads as turned nowhere, its links unchecked. restarts: (m,) where another path starts,
    as `check_reach` takes them (several paths judged at once)."""
    index = np.arange(len(traj)) if index is None else index
    if np.ndim(T_base_part) == 3:  # one per pose of `traj` (external axes)
        T_base_part = np.asarray(T_base_part)[index]
    if sensor_ok is None and obstacles is not None:
        sensor_ok = sensor_clear_both(traj.poses[index], obstacles)
    out: list[np.ndarray] = []
    for k, poses in enumerate((traj.poses[index], traj.poses[index] @ HALF_TURN)):
        flange = T_base_part @ poses @ inv_tcp
        if obstacles is None:  # reach alone: where `check_reach` would find joints
            good = solvable(arm.inverse(flange), arm.joint_limits)
            out.append(good if sensor_ok is None else good & sensor_ok[k])
            continue
        swath, scanning = traj.swath[index], traj.scanning[index]
        joints = check_reach(flange, arm, swath=swath, scanning=scanning, restarts=restarts).joints
        good = ~np.isnan(joints).any(axis=1)
        if sensor_ok is not None:
            good &= sensor_ok[k]
        if k == 1 and choosing is not None:
            # The links only take poses away: where even reach and the sensor keep no
            # more of the pass turned than its links leave as planned, it is not turned.
            passes, at = np.unique(swath, return_inverse=True)
            kept_planned = np.bincount(at, out[0] & choosing, len(passes))
            could_turned = np.bincount(at, good & choosing, len(passes))
            beaten = (could_turned <= kept_planned)[at]
            good &= ~beaten
            joints = np.where(beaten[:, None], np.nan, joints)  # not checked
        good &= ~check_links(arm, joints, obstacles, T_base_part, exact=exact).colliding
        out.append(good)
    return out[0], out[1]


def sensor_clear_both(poses: np.ndarray, obstacles: CellObstacles) -> tuple[np.ndarray, np.ndarray]:
    """Whether the sensor body keeps its clearance at `poses` as planned and turned."""
    return obstacles.sensor_clear(poses), obstacles.sensor_clear(poses @ HALF_TURN)


def turned_passes(swath: np.ndarray, planned: np.ndarray, turned: np.ndarray) -> np.ndarray:
    """The swath indices whose poses are kept more often turned than as planned."""
    passes = np.unique(swath)
    gain = np.bincount(np.searchsorted(passes, swath), turned.astype(int) - planned, len(passes))
    return passes[gain > 0]


def kept_by_pass(swath: np.ndarray, planned: np.ndarray, turned: np.ndarray) -> np.ndarray:
    """(m,) bool: the poses kept, each pass flown the better way."""
    return np.where(np.isin(swath, turned_passes(swath, planned, turned)), turned, planned)


def most_kept(
    swath: np.ndarray, counted: np.ndarray, planned: np.ndarray, turned: np.ndarray
) -> float:
    """The most a placement could keep of the poses' `counted` weights (0: not counted),
    each pass flown the better way: per pass, the larger of the sums kept as planned and
    turned."""
    passes, at = np.unique(swath, return_inverse=True)
    as_planned = np.bincount(at, planned * counted, len(passes))
    as_turned = np.bincount(at, turned * counted, len(passes))
    return float(np.maximum(as_planned, as_turned).sum())


__all__ = [
    "HALF_TURN",
    "flyable_poses",
    "kept_by_pass",
    "most_kept",
    "sensor_clear_both",
    "turned_passes",
]
