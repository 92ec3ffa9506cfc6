"""`place`: the part's pose on the table from which an arm flies every pose of a plan."""

from __future__ import annotations

from scanplan.core.limits import TCP_MM
from scanplan.core.plan import Plan
from scanplan.jobs.planned import ProgressBar, Say, no_bar, plan_cell, planned_part, silent
from scanplan.robot import get_robot
from scanplan.robot.export import parse_pose_arg
from scanplan.robot.export.rotations import IDENTITY_POSE
from scanplan.robot.links import obstacles_for
from scanplan.robot.place import Placement, place


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
    (None: the flange, said) flies every pose of `plan`, its links clear of the part, the
    table and the fixtures the plan records."""
    arm = get_robot(robot)  # a bad arm is named before a missing part
    the_part = planned_part(
        plan, part, units, "the arm's links are checked against the part",
        other_part=part is not None, say=say,
    )  # fmt: skip
    spec = plan.spec
    obstacles = obstacles_for(the_part, plan_cell(plan, the_part), spec.sensor, spec.clearance_mm)
    if tcp is None:
        say(f"--tcp not given: {IDENTITY_POSE} (the sensor origin is the flange)")
    with bar("searching a placement"):
        return place(
            plan.traj,
            arm,
            parse_pose_arg(tcp or IDENTITY_POSE, TCP_MM),
            heights,
            yaw_step_deg,
            obstacles=obstacles,
        )


def placement_lines(result: Placement) -> list[str]:
    """The placement found as --part-pose, and what bounds it."""
    m = result.report.worst_margins()
    lines = [f"--part-pose {result.pose_arg()}", result.report.summary()]
    if result.links is not None:
        lines.append(result.links.summary())
    lines.append(
        f"worst margins: joint limit {m['limit_deg']:.1f} deg, wrist {m['wrist_deg']:.1f} deg, "
        f"elbow {m['elbow_deg']:.1f} deg, shoulder {m['shoulder_mm']:.0f} mm "
        f"({result.evaluated} placements in {result.seconds:.1f} s)"
    )
    return lines
