"""Whether an arm flies a plan as its program would: the one check `export` and the demo run
before writing a program (reach, joint limits, configuration flips, the arm's column beside
the table or on it, its links and the sensor body against the part, the table block and the
fixtures).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from scanplan.core.plan import Plan
from scanplan.core.sensor_spec import SensorSpec
from scanplan.core.trajectory import Trajectory, pass_entries
from scanplan.robot.axes import ExternalAxes, axis_steps, part_poses
from scanplan.robot.base import Robot
from scanplan.robot.joint_moves import TOUCH_MM, sensor_swept
from scanplan.robot.links import (
    LinkClearance,
    LinkReport,
    check_links,
    obstacles_for,
    stands_in_cell,
)
from scanplan.robot.reach import ReachReport, check_reach
from scanplan.robot.straight_moves import blocked_steps
from scanplan.world.capsule_collision import CellObstacles
from scanplan.world.cell import Cell
from scanplan.world.collision import checker_for
from scanplan.world.part import Part

# The stands along a track the arm's column is checked at, this far apart at most.
RAIL_STEP_MM = 100.0


@dataclass(frozen=True, eq=False)  # array fields: == would be ambiguous
class Flyability:
    """What `check_flyable` found.

    reach: the reach check (its `joints` (n, 6) rad, NaN where none was found);
    links: the arm's link capsules against the cell; touching: (n,) bool, the sensor body
    in the part, table or a fixture; problems: (first pose, what, summary) of each kind of
    failure, none when the arm flies the plan; blocked_lines: the poses reached by a long
    straight move (across poses a fit gave up) the arm cannot fly (`straight_moves`);
    swept: the poses entered by a joint move along which the sensor body goes into the
    cell (`joint_moves.sensor_swept`).
    """

    reach: ReachReport
    links: LinkReport
    touching: np.ndarray
    problems: list[tuple[int, str, str]]
    blocked_lines: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    swept: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def flyable(self) -> bool:
        return not self.problems

    @property
    def joints(self) -> np.ndarray:
        return self.reach.joints

    @property
    def sensor_clear(self) -> bool:
        return not (self.touching.any() or len(self.swept))

    def sensor_summary(self) -> str:
        """What the sensor body's checks found, in a line."""
        if self.sensor_clear:
            return "sensor body: clear of the cell at every pose and along every joint move"
        return (
            f"sensor body: in the cell at {int(self.touching.sum())} poses, swung into it by "
            f"{len(self.swept)} joint moves"
        )

    def first_problem(self, swath: np.ndarray) -> str:
        """'pose 12 (pass 3) is out of reach; <summaries>': the first offending pose."""
        first, what, _ = min(self.problems)
        summary = "; ".join(p[2] for p in self.problems)
        return f"pose {first} (pass {int(swath[first])}) {what}; {summary}"


def stands_clear(
    arm: Robot, T_base_part: np.ndarray, axes: ExternalAxes | None, obstacles: CellObstacles
) -> bool:
    """Whether the arm's column stands beside the table block or on its top
    (`links.stands_in_cell`) wherever its track can take it: the rail is there over its whole
    length, so every stand along it, not only those a plan uses, is checked. A turntable
    turns the part, not the table, so it does not move the column's stand."""
    T = np.asarray(T_base_part, dtype=np.float64)[None]
    if axes is not None and axes.track is not None and axes.track.direction is not None:
        half = axes.track.length_mm / 2
        values = np.zeros((max(2, math.ceil(2 * half / RAIL_STEP_MM) + 1), len(axes.names)))
        values[:, -1] = np.linspace(-half, half, len(values))  # the track's is the last axis
        T = axes.base_part(T_base_part, values)
    return bool(stands_in_cell(arm, T, obstacles).all())


def arm_along(
    traj: Trajectory,
    arm: Robot,
    T_base_part: np.ndarray,
    T_flange_sensor: np.ndarray,
    obstacles: CellObstacles,
    axes: ExternalAxes | None = None,
    entries: Mapping[int, np.ndarray] | None = None,
) -> tuple[ReachReport, LinkReport]:
    """The arm's reach along `traj` (each pass entered where the plan enters it,
    `pass_entries`, on the joints `entries` gives or else on a configuration that keeps
    the links clear) and its links in the cell at every pose and on every joint move: into
    each pass, and where the turntable turns."""
    T_all = part_poses(T_base_part, traj.external, axes)
    flange = T_all @ traj.poses @ np.linalg.inv(T_flange_sensor)
    entry = pass_entries(traj)
    reach = check_reach(
        flange,
        arm,
        swath=traj.swath,
        scanning=traj.scanning,
        cell=LinkClearance(arm, obstacles, T_all),
        entries=entries,
        entry=entry,
    )
    links = check_links(arm, reach.joints, obstacles, T_all, entry | axis_steps(traj, axes))
    return reach, links


def check_flyable(
    traj: Trajectory,
    arm: Robot,
    T_base_part: np.ndarray,
    T_flange_sensor: np.ndarray,
    part: Part,
    cell: Cell,
    sensor: SensorSpec,
    obstacles: CellObstacles | None = None,
    axes: ExternalAxes | None = None,
    entries: Mapping[int, np.ndarray] | None = None,
) -> Flyability:
    """The arm's reach along the flange poses of `traj` (part frame, sensor poses) with the
    part at `T_base_part` and the sensor at `T_flange_sensor` (mm), its links along that
    path and every joint move into a pass, and the sensor body, against `part` in `cell`.
    obstacles: `obstacles_for(part, cell)` if the caller has it (a fit just built it);
    None: built here. axes: the external axes the plan's values per pose (`traj.external`)
    are of (the part moved pose by pose; `robot.axes`), None: the arm alone. entries: the
    joints each pass is entered with (None: as the plan records them for this arm, pose and
    TCP, `ArmRecord.entry_joints`); passes without are entered on the configuration that
    keeps the links clear."""
    plan = Plan.of(traj)
    clearance = plan.spec.clearance_mm  # the links keep the plan's
    if entries is None and plan.arm is not None:
        entries = plan.arm.entry_joints(arm.name, T_base_part, T_flange_sensor)
    if obstacles is None:
        obstacles = obstacles_for(part, cell, sensor, clearance)
    reach, links = arm_along(traj, arm, T_base_part, T_flange_sensor, obstacles, axes, entries)
    touching = checker_for(part, sensor, cell).check(traj.poses, TOUCH_MM).touching
    problems = [(*reach.first_problem(), reach.summary())] if not reach.reachable else []
    T_all = part_poses(T_base_part, traj.external, axes)
    inv_tcp = np.linalg.inv(T_flange_sensor)
    entry = pass_entries(traj)
    lines = blocked_steps(arm, traj, T_all, inv_tcp, reach.joints, entry, obstacles)
    if len(lines):
        problems.append(
            (
                int(lines[0]),
                f"is reached by a straight move from pose {int(lines[0]) - 1} the arm cannot "
                "fly (out of reach, a flip or a link or the sensor in the cell on the way)",
                f"straight moves: {len(lines)} the arm cannot fly",
            )
        )
    moves = entry | axis_steps(traj, axes)  # where the arm makes joint moves
    swept = sensor_swept(arm, reach.joints, moves, T_all, T_flange_sensor, obstacles, TOUCH_MM)
    if len(swept):
        problems.append(
            (
                int(swept[0]),
                "is reached by a joint move that swings the sensor body into the part, table "
                "or a fixture",
                f"joint moves: {len(swept)} swing the sensor body into the cell",
            )
        )
    if not links.clear:
        problems.append((links.first(), links.describe(links.first()), links.summary()))
    if not stands_clear(arm, T_base_part, axes, obstacles):
        base = np.linalg.inv(np.asarray(T_base_part, dtype=np.float64))[:3, 3]
        where = ", ".join(f"{v:.0f}" for v in base)
        problems.append(
            (
                0,
                f"stands the arm's column in the table (base at {where} mm in the part's frame)",
                "column: the arm's base stands in the table block; place it beside the table",
            )
        )
    if touching.any():
        first = int(np.argmax(touching))
        problems.append(
            (
                first,
                "puts the sensor body into the part, table or a fixture",
                f"sensor: {int(touching.sum())} poses touching the cell",
            )
        )
    return Flyability(reach, links, touching, problems, lines, swept)
