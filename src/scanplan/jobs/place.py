"""`place`: the part's pose on the table from which an arm flies every pose of a plan."""

from __future__ import annotations

import numpy as np

from scanplan.core.limits import TCP_MM
from scanplan.core.plan import Plan
from scanplan.jobs.planned import ProgressBar, Say, no_bar, plan_cell, planned_part, silent
from scanplan.robot import get_robot
from scanplan.robot.axes import with_disk
from scanplan.robot.base import Robot
from scanplan.robot.export import parse_pose_arg
from scanplan.robot.export.rotations import IDENTITY_POSE
from scanplan.robot.flyable import check_flyable
from scanplan.robot.links import obstacles_for
from scanplan.robot.place import Placement, place
from scanplan.robot.program import axes_of
from scanplan.world.capsule_collision import CellObstacles
from scanplan.world.part import Part


def place_plan(
    plan: Plan,
    robot: str,
    tcp: str | None,
    heights: tuple[float, float] | None,
    yaw_step_deg: float,
    part: str | None = None,
    units: str | None = None,
    say: Say = silent,
    bar: ProgressBar = no_bar,
) -> Placement:
    """Search the part's pose (x, y, z, yaw) from which `robot` with the sensor at `tcp`
    (None: the plan's for the arm it was made for, else the flange; said) flies every pose
    of `plan`, its links clear of the part, the table and the fixtures the plan records. A
    plan made for this arm and TCP is first judged where it was planned, as `export` judges
    it: if the arm flies it there, that is the answer (no search)."""
    arm = get_robot(robot)  # a bad arm is named before a missing part
    the_part = planned_part(
        plan, part, units, "the arm's links are checked against the part",
        other_part=part is not None, say=say,
    )  # fmt: skip
    spec = plan.spec
    obstacles = obstacles_for(the_part, plan_cell(plan, the_part), spec.sensor, spec.clearance_mm)
    same_arm = plan.arm is not None and plan.arm.robot == robot
    if tcp is None and same_arm and plan.arm is not None:
        say(f"--tcp {plan.arm.record.get('tcp', '')} (the plan's)")
        T_tcp = plan.arm.T_flange_sensor
    else:
        if tcp is None:
            say(f"--tcp not given: {IDENTITY_POSE} (the sensor origin is the flange)")
        T_tcp = parse_pose_arg(tcp or IDENTITY_POSE, TCP_MM)
    if same_arm:
        with bar("judging the plan's placement"):
            found = planned_placement(plan, arm, T_tcp, the_part, obstacles)
        if found is not None:
            say("the plan's own placement flies every pose (as export checks it): kept")
            return found
    if plan.traj.external is not None:
        # The search places the part for the arm alone: the plan's values of its axes would
        # be read as turning nothing, and its answer would be about another cell.
        beside = f" and {robot} does not fly it from its placement with them" if same_arm else ""
        raise ValueError(
            f"the plan is flown with external axes (a turntable or track){beside}; place "
            "searches a placement for the arm alone: plan again with --robot "
            f"{robot} and --positioner to place the arm with its axes"
        )
    with bar("searching a placement"):
        return place(plan.traj, arm, T_tcp, heights, yaw_step_deg, obstacles=obstacles)


def planned_placement(
    plan: Plan, arm: Robot, T_tcp: np.ndarray, part: Part, obstacles: CellObstacles
) -> Placement | None:
    """The placement `plan` records for the arm it was made for, if `arm` holding the
    sensor at `T_tcp` flies every pose from there as `export` checks it (each pass entered
    on the joints recorded); None otherwise. A plan moved by external axes is judged as
    export judges it, with them (their stand and values are the plan's)."""
    recorded = plan.arm
    if recorded is None or not np.allclose(T_tcp, recorded.T_flange_sensor, atol=1e-6):
        return None
    axes = axes_of(plan)
    cell = plan_cell(plan, part)
    if axes is not None:  # the part moved pose by pose, the turntable's disk in the cell
        cell = with_disk(cell, axes)
    checked = check_flyable(
        plan.traj, arm, recorded.T_base_part, T_tcp, part, cell, plan.spec.sensor,
        obstacles if axes is None else None, axes=axes,
    )  # fmt: skip
    if not checked.flyable:
        return None
    return Placement(recorded.T_base_part, checked.reach, None, 0, 0.0, checked.links)


def placement_lines(result: Placement) -> list[str]:
    """The placement found as --part-pose, and what bounds it."""
    m = result.report.worst_margins()
    lines = [f"--part-pose {result.pose_arg()}", result.report.summary()]
    if result.links is not None:
        lines.append(result.links.summary())
    lines.append(
        f"worst margins: joint limit {m['limit_deg']:.1f} deg, wrist {m['wrist_deg']:.1f} deg, "
        f"elbow {m['elbow_deg']:.1f} deg, shoulder {m['shoulder_mm']:.0f} mm"
        + (
            " (the plan's own placement, not searched)"
            if result.score is None
            else f" ({result.evaluated} placements in {result.seconds:.1f} s)"
        )
    )
    return lines
