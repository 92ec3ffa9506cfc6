"""An arm standing where a placement puts the part, as the view choice asks of each candidate
view what the arm flies of it: each pass as planned or turned, its poses the arm cannot
reach or that put a link or the sensor body into the cell given up (the quick judgement;
`fit.fit_to_robot` makes the plan flyable).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from scanplan.core.context import PlanContext
from scanplan.core.trajectory import Trajectory
from scanplan.robot.base import inv_rigid
from scanplan.robot.fit_marks import renumbered_passes
from scanplan.robot.flown_poses import (
    HALF_TURN,
    flyable_poses,
    most_kept,
    sensor_clear_both,
    turned_passes,
)
from scanplan.robot.links import obstacles_for
from scanplan.robot.nearest_joints import solvable
from scanplan.robot.presets import get_robot
from scanplan.world.capsule_collision import CellObstacles
from scanplan.world.cell import planned_cell
from scanplan.world.part import Part

# The turns about the beam a nominal sensor pose is tried at by `PlacedArm.reaches`: the
# raster's direction, which sets it, is chosen only when the view is planned.
NOMINAL_TURNS = 4


class PlacedArm:
    """An arm standing where `T_base_part` puts the part, as the view choice asks of each
    candidate view what the arm flies of it (`flown`). Picklable (sent to the view
    workers): the cell's obstacles are built where they are first needed, once per part."""

    def __init__(
        self, robot: str | Path, tcp: np.ndarray, T_base_part: np.ndarray, context: PlanContext
    ) -> None:
        self.robot, self.context = robot, context
        self.tcp, self.T_base_part = np.asarray(tcp), np.asarray(T_base_part)
        self._obstacles: tuple[int, CellObstacles] | None = None

    def __getstate__(self) -> dict:
        return self.__dict__ | {"_obstacles": None}

    def among(self, part: Part, obstacles: CellObstacles) -> PlacedArm:
        """This arm judging `part` among `obstacles` (`obstacles_for` its context's cell,
        built by the caller already): not built again in this process."""
        self._obstacles = (id(part), obstacles)
        return self

    def obstacles(self, part: Part) -> CellObstacles:
        if self._obstacles is None or self._obstacles[0] != id(part):
            spec = self.context.spec
            cell = planned_cell(self.context, part)
            self._obstacles = (
                id(part),
                obstacles_for(part, cell, spec.sensor, spec.clearance_mm),
            )
        return self._obstacles[1]

    @property
    def stands_at(self) -> np.ndarray:
        """(3,) the arm's base in the part's frame."""
        return inv_rigid(self.T_base_part)[:3, 3]

    @property
    def shoulder_at(self) -> np.ndarray:
        """(3,) the arm's shoulder (where its upper arm starts, the joints at zero) in the
        part's frame: what its reach is measured from."""
        segments, _, names = get_robot(self.robot).link_capsules(np.zeros((1, 6)))
        shoulder = np.r_[segments[0, names.index("upper arm"), 0], 1.0]  # its first end
        return (inv_rigid(self.T_base_part) @ shoulder)[:3]

    def aiming(self) -> PlacedArm | None:
        """This arm, as the views aimed at what it misses are aimed for it
        (`views.missed_views`)."""
        return self

    def reaches(self, points: np.ndarray, axis: np.ndarray) -> np.ndarray:
        """(k,) bool: whether the arm reaches, within its joint limits, the sensor looking
        at each of `points` (k, 3; part frame) along -`axis` (3,) from the working distance,
        at one of `NOMINAL_TURNS` turns about the beam: whether a view along `axis` may fly
        anything there. The view's poses lean from its axis as the surface does (the door's
        top view: 92 % of its footprints reached so, 80 % of its poses), and the links and
        the cell are left to `flown`: what it may fly, not what it will."""
        arm = get_robot(self.robot)
        beam = -np.asarray(axis, float) / np.linalg.norm(axis)
        side = np.cross(beam, [1.0, 0.0, 0.0])
        if np.linalg.norm(side) < 1e-6:
            side = np.cross(beam, [0.0, 1.0, 0.0])
        side /= np.linalg.norm(side)
        turns = np.arange(NOMINAL_TURNS) * (2 * np.pi / NOMINAL_TURNS)
        x = np.cos(turns)[:, None] * side + np.sin(turns)[:, None] * np.cross(beam, side)
        R = np.stack([x, np.cross(beam, x), np.broadcast_to(beam, x.shape)], axis=-1)
        origin = np.asarray(points, float) - self.context.spec.working_distance_mm * beam
        inv_tcp = inv_rigid(self.tcp)
        ok = np.zeros(len(origin), bool)
        for turned in R:  # each turn asked only of the points no turn before reached
            todo = np.flatnonzero(~ok)
            if not len(todo):
                break
            sensor = np.broadcast_to(np.eye(4), (len(todo), 4, 4)).copy()
            sensor[:, :3, :3] = turned
            sensor[:, :3, 3] = origin[todo]
            q = arm.inverse(self.T_base_part @ sensor @ inv_tcp)
            ok[todo] = solvable(q, arm.joint_limits)
        return ok

    def moves_clear(self, part: Part, traj: Trajectory) -> bool:
        """Whether the sensor body keeps its clearance of the cell at every pose of `traj`
        that does not scan: `flown` judges the scanning poses, and takes the moves between
        them as planned clear, which a view moved after planning must be checked for."""
        moves = traj.poses[~traj.scanning]
        return bool(self.obstacles(part).sensor_clear(moves).all())

    def flown(self, part: Part, traj: Trajectory) -> Trajectory:
        """`traj` as this arm flies it, quickly judged: each pass as planned or turned half
        a turn about the beam (whichever keeps more), its scanning poses that are out of
        reach or beyond the limits, or put a link or the sensor body into the cell, given
        up (a pass goes on after them as a new pass). Configuration flips are left to
        `fit_to_robot`, which splits a pass there and keeps its poses. `traj` itself when
        the arm flies all of it as planned."""
        return self._flown(part, traj, None)

    def _flown(
        self, part: Part, traj: Trajectory, sensor_ok: tuple[np.ndarray, np.ndarray] | None
    ) -> Trajectory:
        """`flown`, the sensor body's verdict at its poses as planned and turned
        (`sensor_clear_both`) given if known."""
        arm = get_robot(self.robot)
        obstacles = self.obstacles(part)
        inv_tcp = np.linalg.inv(self.tcp)
        planned, turned = flyable_poses(
            traj,
            arm,
            self.T_base_part,
            inv_tcp,
            obstacles,
            sensor_ok=sensor_ok,
            exact=False,
            choosing=traj.scanning,
        )
        scanning = traj.scanning
        better = turned_passes(traj.swath[scanning], planned[scanning], turned[scanning])
        turn = np.isin(traj.swath, better)
        keep = np.where(turn, turned, planned) | ~scanning
        if keep.all() and not turn.any():
            return traj  # flown as planned: the caller may reuse what it knows of it
        poses = np.where(turn[:, None, None], traj.poses @ HALF_TURN, traj.poses)
        swath = renumbered_passes(traj, keep, traj.swath, np.zeros(len(traj), bool))
        return replace(traj, poses=poses).subset(keep, swath)

    def flown_beyond(self, part: Part, traj: Trajectory, least: int) -> Trajectory | None:
        """`flown`, where it keeps more than `least` scanning poses of `traj`, else None. The
        links only take poses away: where reach and the sensor alone, each pass the better
        way, keep no more, its links are not checked (most views moved to fly more do not,
        and each pose's reach is one array operation, `flyable_poses` without a cell)."""
        arm = get_robot(self.robot)
        sensor_ok = sensor_clear_both(traj.poses, self.obstacles(part))
        inv_tcp = np.linalg.inv(self.tcp)
        reached = flyable_poses(traj, arm, self.T_base_part, inv_tcp, None, sensor_ok=sensor_ok)
        if most_kept(traj.swath, traj.scanning.astype(float), *reached) <= least:
            return None
        flown = self._flown(part, traj, sensor_ok)
        return flown if flown.scanning.sum() > least else None


__all__ = ["PlacedArm"]
