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

PageOutOpt = Annotated[
    Path, typer.Option("-o", "--output", metavar="FILE", help="output file: the page (.html)")
]
ViewRobotOpt = Annotated[
    str | None,
    typer.Option(
        metavar="ARM",
        help="arm to draw: ur3e, ur5e, ur10e, kr6-r900, irb2400, lrmate200id or a TOML file "
        "of its kinematics; 'none' for no arm; default: the arm the plan was made for, if any",
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
    fixtures, the passes coloured by the side their view looks from, the moves in grey and,
    for a plan made for an arm (or with --robot), the arm at the first, middle and last pose
    of each pass, see-through, with the poses it cannot reach or where a link collides
    marked in red."""
    # Deferred: the page loads plotly, the arm the kinematics and FCL.
    from scanplan.core.plan import read_plan
    from scanplan.jobs.view import view_plan

    if str(output) in ("", ".") or output.is_dir():
        raise ValueError(f"-o {str(output)!r} is a directory: give the page's file name")
    if output.exists() and output.resolve() == trajectory.resolve():
        raise ValueError(f"-o {output} is the plan itself: give the page another name")
    plan = read_plan(trajectory)
    line = view_plan(
        plan, output, robot, part_pose, tcp, part, units, lambda text: typer.echo(text, err=True)
    )
    typer.echo(line)
