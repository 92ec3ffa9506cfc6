"""`scanplan view`: the 3-D page of a plan — part, table, fixtures, passes by view and the
arm along them — written in seconds, without simulating the scan.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from scanplan.cli.common import user_errors
from scanplan.cli.options import (
    PartPoseOpt,
    PlannedPartOpt,
    PlannedUnitsOpt,
    TcpOpt,
    TrajectoryArg,
)
from scanplan.cli.robot import arm_of, planned_cell

PageOutOpt = Annotated[Path, typer.Option("-o", "--output", help="the page to write (HTML)")]
ViewRobotOpt = Annotated[
    str | None,
    typer.Option(
        help="arm to draw: ur3e, ur5e, ur10e, kr6-r900, irb2400, lrmate200id or a TOML file "
        "of OPW parameters; 'none' for no arm; default: the arm the plan was made for, if any"
    ),
]


@user_errors
def view_cmd(
    trajectory: TrajectoryArg,
    output: PageOutOpt,
    robot: ViewRobotOpt = None,
    part_pose: PartPoseOpt = None,
    tcp: TcpOpt = None,
    part: PlannedPartOpt = None,
    units: PlannedUnitsOpt = None,
):
    """Write a plan's 3-D page without simulating the scan: the part on its table, the
    fixtures, the passes coloured by view, the moves in grey and, for a plan made for an arm
    (or with --robot), the arm at the first, middle and last pose of each pass, with the
    poses it cannot reach or where a link collides marked in red."""
    # Deferred: the page loads plotly, the arm the kinematics and FCL.
    from scanplan.core.trajectory import read_trajectory
    from scanplan.judging.report.html import write_scene_page
    from scanplan.judging.report.scene import check_arm, scene_figure
    from scanplan.robot import get_robot
    from scanplan.robot.base import pose_arg

    if str(output) in ("", ".") or output.is_dir():
        raise ValueError(f"-o {str(output)!r} is a directory: give the page's file name")
    if output.exists() and output.resolve() == trajectory.resolve():
        raise ValueError(f"-o {output} is the plan itself: give the page another name")
    traj = read_trajectory(trajectory)
    if robot is not None and robot.lower() != "none":
        get_robot(robot)  # a bad arm is named before the notes on its poses
    with_arm = robot.lower() != "none" if robot is not None else bool(traj.meta.get("robot"))
    if not with_arm:
        for option, value in (("--part-pose", part_pose), ("--tcp", tcp)):
            if value is not None:
                raise ValueError(f"{option} needs --robot: the arm it places")
    the_part, cell = planned_cell(traj, part, units, "the page draws the part")
    arm = None
    if with_arm:
        name, T_base_part, T_flange_sensor = arm_of(traj, robot, part_pose, tcp, say_recorded=False)
        arm = check_arm(traj, name, T_base_part, T_flange_sensor, the_part, cell)
    n_views = max(len(traj.meta.get("views") or ()), 1)
    title = f"{the_part.name}: {trajectory.name}"
    notes = [
        f"{traj.planner or 'plan'}: {len(traj)} poses, {n_views} view"
        f"{'s' * (n_views > 1)}, {int(traj.scanning.sum())} scanning; passes coloured by "
        "view, moves in grey; click a legend entry to hide it."
    ]
    if arm is not None:
        notes.append(
            f"{arm.robot} at --part-pose {pose_arg(arm.T_base_part)}, drawn as the capsules "
            "its links are checked with at the first, middle and last pose of each pass (the "
            "slider under the scene steps through them); red: poses it cannot reach or where "
            "a link collides."
        )
        notes += list(arm.summaries)
    write_scene_page(output, scene_figure(the_part, traj, cell, arm, title), title, notes)
    size_mb = output.stat().st_size / 1e6
    what = (
        f"arm {arm.robot} at {pose_arg(arm.T_base_part)} ({int(arm.unreachable.sum())} "
        f"unreachable, {int(arm.colliding.sum())} link collisions)"
        if arm is not None
        else "no arm"
    )
    typer.echo(
        f"view: {len(traj)} poses, {n_views} view{'s' * (n_views > 1)}, {what} -> {output} "
        f"({size_mb:.1f} MB)"
    )
