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
from scanplan.robot.fit import renumbered_passes
from scanplan.robot.flown_poses import HALF_TURN, flyable_poses, turned_passes
from scanplan.robot.links import obstacles_for
from scanplan.robot.presets import get_robot
from scanplan.world.capsule_collision import CellObstacles
from scanplan.world.cell import planned_cell
from scanplan.world.part import Part


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

    def flown(self, part: Part, traj: Trajectory) -> Trajectory:
        """`traj` as this arm flies it, quickly judged: each pass as planned or turned half
        a turn about the beam (whichever keeps more), its scanning poses that are out of
        reach or beyond the limits, or put a link or the sensor body into the cell, given
        up (a pass goes on after them as a new pass). Configuration flips are left to
        `fit_to_robot`, which splits a pass there and keeps its poses. `traj` itself when
        the arm flies all of it as planned."""
        arm = get_robot(self.robot)
        obstacles = self.obstacles(part)
        inv_tcp = np.linalg.inv(self.tcp)
        planned, turned = flyable_poses(
            traj, arm, self.T_base_part, inv_tcp, obstacles, exact=False, choosing=traj.scanning
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


__all__ = ["PlacedArm"]
