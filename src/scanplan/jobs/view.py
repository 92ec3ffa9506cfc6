"""`view`: a plan's 3-D page — part, table, fixtures, passes by view and the arm along them —
written in seconds, without simulating the scan.
"""

from __future__ import annotations

from pathlib import Path

from scanplan.core.plan import Plan
from scanplan.jobs.export import arm_of
from scanplan.jobs.planned import Say, plan_cell, planned_part, silent
from scanplan.judging.report.html import write_scene_page
from scanplan.judging.report.scene import scene_figure
from scanplan.judging.report.scene_arm import ArmPoses, check_arm
from scanplan.robot import get_robot
from scanplan.robot.base import pose_arg
from scanplan.robot.program import axes_of


def view_plan(
    plan: Plan,
    output: Path,
    robot: str | None = None,
    part_pose: str | None = None,
    tcp: str | None = None,
    part: str | None = None,
    units: str | None = None,
    say: Say = silent,
) -> str:
    """Write the plan's page to `output`; the arm drawn is the plan's (or `robot`; 'none':
    no arm). Returns the line that says what the page shows."""
    if robot is not None and robot.lower() != "none":
        get_robot(robot)  # a bad arm is named before the notes on its poses
    with_arm = robot.lower() != "none" if robot is not None else plan.arm is not None
    if not with_arm:
        for option, value in (("--part-pose", part_pose), ("--tcp", tcp)):
            if value is not None:
                raise ValueError(f"{option} needs --robot: the arm it places")
    the_part = planned_part(
        plan, part, units, "the page draws the part", other_part=part is not None, say=say
    )
    cell = plan_cell(plan, the_part)
    arm: ArmPoses | None = None
    if with_arm:
        name, T_base_part, T_flange_sensor = arm_of(plan, robot, part_pose, tcp, lambda _: None)
        entries = (
            None if plan.arm is None else plan.arm.entry_joints(name, T_base_part, T_flange_sensor)
        )
        arm = check_arm(
            plan.traj, name, T_base_part, T_flange_sensor, the_part, cell, axes_of(plan), entries
        )
    title = f"{the_part.name}: {Path(plan.where.removeprefix('plan ')).name}"
    notes = [
        f"{plan.planner or 'plan'}: {plan.counts()}, {len(plan.traj)} poses; passes coloured "
        "by the side their view looks from (hover over a pass for its view), moves in grey; "
        "click a legend entry to hide it, the arm's to hide the arm."
    ]
    if arm is not None:
        notes.append(
            f"{arm.robot} at --part-pose {pose_arg(arm.T_base_part)}, drawn see-through as "
            "the capsules its links are checked with at the first, middle and last pose of each "
            "pass (the slider under the scene steps through them); red: poses it cannot reach "
            "or where a link collides."
        )
        notes += list(arm.summaries)
    write_scene_page(output, scene_figure(the_part, plan.traj, cell, arm, title), title, notes)
    what = (
        f"arm {arm.robot} at {pose_arg(arm.T_base_part)} ({int(arm.unreachable.sum())} "
        f"unreachable, {int(arm.colliding.sum())} link collisions)"
        if arm is not None
        else "no arm"
    )
    size_mb = output.stat().st_size / 1e6
    return f"view: {plan.counts()}, {len(plan.traj)} poses, {what} -> {output} ({size_mb:.1f} MB)"
