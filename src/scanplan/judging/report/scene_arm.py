"""The arm along a plan as the 3-D page draws it: checked as `export` checks it (reach,
limits, its links in the cell, each pass entered as the plan records), and the poses it is
drawn at.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from scanplan.core.plan import Plan
from scanplan.core.trajectory import Trajectory
from scanplan.judging.report.scene_axes import axis_capsules
from scanplan.robot import get_robot
from scanplan.robot.axes import ExternalAxes, part_poses, plan_axes, with_disk
from scanplan.robot.flyable import arm_along
from scanplan.robot.links import obstacles_for
from scanplan.robot.reach import pass_starts
from scanplan.world.cell import Cell, planned_cell
from scanplan.world.part import Part

# The arm is drawn at each pass's first, middle and last pose, at most this many poses in
# all (passes taken evenly when a plan has more): beyond that the arms hide the part.
MAX_ARM_POSES = 48
# The sensor drawn from the flange to its origin (the TCP) as a capsule of this radius.
SENSOR_RADIUS_MM = 25.0


@dataclass(frozen=True)
class ArmPoses:
    """The arm along a plan, checked as `export` checks it, with the poses to draw.

    robot: the arm's name; T_base_part (4, 4) the part in its base frame (mm);
    unreachable: (n,) no joint solution, or none within the joint limits;
    colliding: (n,) a link within the clearance of the part, the table or a fixture;
    shown: (m,) indices of the poses drawn; capsules_part: (m, k, 2, 3) their links'
    segment ends in the part frame (mm), the last one flange to sensor origin; radii: (k,)
    mm; summaries: the reach and link checks' one-line summaries. axes: the external axes
    (None: the arm alone), their values at the poses drawn `shown_axes` (m, k), and the
    part's pose at each pose drawn `T_base_part_shown` (m, 4, 4).
    """

    robot: str
    T_base_part: np.ndarray
    unreachable: np.ndarray
    colliding: np.ndarray
    shown: np.ndarray
    capsules_part: np.ndarray
    radii: np.ndarray
    summaries: tuple[str, ...]
    axes: ExternalAxes | None = None
    shown_axes: np.ndarray | None = None

    @property
    def base_part(self) -> np.ndarray:
        """(3,) the robot base's origin in the part frame, mm."""
        return np.linalg.inv(self.T_base_part)[:3, 3]


def pass_runs(traj: Trajectory) -> list[np.ndarray]:
    """The pose indices of each pass: runs of scanning poses of one swath."""
    starts = np.flatnonzero(pass_starts(traj.swath, traj.scanning))
    runs = []
    for s in starts:
        e = s
        while e + 1 < len(traj) and traj.scanning[e + 1] and traj.swath[e + 1] == traj.swath[s]:
            e += 1
        runs.append(np.arange(s, e + 1))
    return runs


def shown_poses(
    traj: Trajectory, problems: np.ndarray, max_poses: int = MAX_ARM_POSES
) -> np.ndarray:
    """The poses the arm is drawn at: each pass's first, middle and last (passes taken evenly
    if there are too many), and the first pose of each pass where `problems` (n,) is set."""
    runs = pass_runs(traj)
    if len(runs) * 3 > max_poses:
        runs = [runs[i] for i in np.linspace(0, len(runs) - 1, max(max_poses // 3, 1)).astype(int)]
    picked = [r[[0, len(r) // 2, -1]] for r in runs]
    picked += [r[problems[r]][:1] for r in pass_runs(traj)]
    return np.unique(np.concatenate(picked)) if picked else np.zeros(0, dtype=int)


def check_arm(
    traj: Trajectory,
    robot: str,
    T_base_part: np.ndarray,
    T_flange_sensor: np.ndarray,
    part: Part,
    cell: Cell,
    axes: ExternalAxes | None = None,
    entries: Mapping[int, np.ndarray] | None = None,
) -> ArmPoses:
    """The arm `robot` along `traj` (the part at `T_base_part`, the sensor at
    `T_flange_sensor` on the flange; with external `axes`, the part where their values per
    pose put it; each pass entered with the joints `entries` records, as `export` checks
    it): its reach and link checks and the poses to draw."""
    arm = get_robot(robot)
    T_base_part = np.asarray(T_base_part, dtype=np.float64)
    T_all = part_poses(T_base_part, traj.external, axes)
    cell = with_disk(cell, axes)
    # The links keep the clearance the plan was made with, as the sensor does.
    obstacles = obstacles_for(part, cell, clearance_mm=Plan.of(traj).spec.clearance_mm)
    reach, links = arm_along(traj, arm, T_base_part, T_flange_sensor, obstacles, axes, entries)
    unreachable = np.zeros(len(traj), dtype=bool)
    unreachable[np.r_[reach.unreachable, reach.limit_violations].astype(int)] = True
    colliding = np.asarray(links.colliding, dtype=bool)
    shown = shown_poses(traj, unreachable | colliding)
    shown = shown[~np.isnan(reach.joints[shown]).any(axis=1)]  # no joints, no arm to draw
    ends, radii, _ = arm.link_capsules(reach.joints[shown])
    T_part_base = np.linalg.inv(np.broadcast_to(T_all, (len(traj), 4, 4))[shown])
    ends_part = np.einsum("mij,mkej->mkei", T_part_base[:, :3, :3], ends)
    ends_part = ends_part + T_part_base[:, None, None, :3, 3]
    # The sensor on the flange, flange to sensor origin: the arm visibly reaches its pose.
    flange_part = (traj.poses[shown] @ np.linalg.inv(T_flange_sensor))[:, :3, 3]
    tool = np.stack([flange_part, traj.poses[shown, :3, 3]], axis=1)[:, None]
    ends_part = np.concatenate([ends_part.reshape(len(shown), len(radii), 2, 3), tool], 1)
    radii = np.r_[radii, SENSOR_RADIUS_MM]
    shown_axes = None
    if axes is not None and traj.external is not None:
        shown_axes = traj.external[shown]
        extra = axis_capsules(axes, T_part_base)
        ends_part = np.concatenate([ends_part, extra[0]], 1)
        radii = np.r_[radii, extra[1]]
    return ArmPoses(
        arm.name,
        T_base_part,
        unreachable,
        colliding,
        shown,
        ends_part,
        np.asarray(radii, dtype=np.float64),
        (reach.summary(), links.summary()),
        axes,
        shown_axes,
    )


def recorded_scene(part: Part, traj: Trajectory) -> tuple[Cell, ArmPoses | None]:
    """The cell `traj` was planned in around `part` and, for a plan made for an arm, that
    arm along it. ValueError or OSError if a fixture file or the arm's file is gone or the
    record is malformed."""
    plan = Plan.of(traj)
    cell = planned_cell(plan.context, part)
    if plan.arm is None:
        return cell, None
    arm = plan.arm
    axes = plan_axes(arm.record, traj.external, plan.where)
    entries = arm.entry_joints(arm.robot, arm.T_base_part, arm.T_flange_sensor)
    return cell, check_arm(
        traj, arm.robot, arm.T_base_part, arm.T_flange_sensor, part, cell, axes, entries
    )


# ---- traces -------------------------------------------------------------------------------


__all__ = ["ArmPoses", "check_arm", "pass_runs", "recorded_scene", "shown_poses"]
