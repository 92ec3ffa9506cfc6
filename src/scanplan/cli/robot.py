"""`scanplan export` and `place`: a trajectory as a robot program, and the part's pose on the
table from which an arm reaches all of it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from scanplan.cli.common import progress_bar, user_errors
from scanplan.cli.options import (
    PartPoseOpt,
    PlannedPartOpt,
    PlannedUnitsOpt,
    QuietOpt,
    TcpOpt,
    TrajectoryArg,
    bounded,
    within,
)
from scanplan.core.limits import (
    ANGLE_DEG,
    MAX_SCAN_SPEED_MM_S,
    PROFILE_RATE_HZ,
    SIGNED_LENGTH_MM,
    SPEED_MM_S,
    STEP_MM,
    TOLERANCE_MM,
)
from scanplan.core.quantities import PLACE_YAW_STEP_DEG

# ---- export -------------------------------------------------------------------------------
ROBOT_HELP = (
    "arm to check reach on: ur3e, ur5e, ur10e, kr6-r900, irb2400, lrmate200id or a TOML "
    "file of its kinematics; 'none' to skip"
)
ProgramOutOpt = Annotated[
    Path,
    typer.Option(
        "-o",
        "--output",
        metavar="FILE",
        help="output file: the program (.script, .src, .mod, .yaml, .csv); an output folder "
        "for --format rosbag2",
    ),
]
FormatOpt = Annotated[
    str | None,
    typer.Option(
        "--format",
        help="urscript, rapid, krl, ros, rosbag2 or csv; default: the language of the arm's "
        "controller (UR: urscript, KUKA: krl, ABB: rapid), else the output's extension, else "
        "csv for no arm. A language the arm does not run, or an extension of another, is "
        "refused",
        show_default=False,
    ),
]
ProfileRateOpt = Annotated[
    float | None,
    typer.Option(
        metavar="HZ",
        help=f"sensor profile rate, Hz, {PROFILE_RATE_HZ.lo:g} to {PROFILE_RATE_HZ.hi:g}; scan "
        f"speed = rate x spacing, at most {MAX_SCAN_SPEED_MM_S:g} mm/s; default: the plan's",
        show_default=False,
        callback=within(PROFILE_RATE_HZ),
    ),
]
SpacingOpt = Annotated[
    float | None,
    typer.Option(
        metavar="MM",
        help=f"profile spacing on the part, mm, {STEP_MM.lo:g} to {STEP_MM.hi:g}; default: the "
        "plan's",
        show_default=False,
        callback=within(STEP_MM),
    ),
]
TravelSpeedOpt = Annotated[
    float | None,
    typer.Option(
        metavar="MM/S",
        help=f"speed between passes, mm/s, {SPEED_MM_S.lo:g} to {SPEED_MM_S.hi:g}; default: the "
        "plan's",
        show_default=False,
        callback=within(SPEED_MM_S),
    ),
]
ReachRobotOpt = Annotated[
    str | None,
    typer.Option(
        metavar="ARM", help=ROBOT_HELP + "; default: the arm the plan was made for, if any"
    ),
]
ChordTolOpt = Annotated[
    float | None,
    typer.Option(
        "--chord-tol",
        metavar="MM",
        help="how far the thinned, blended path may stray from a planned pose, mm "
        f"({TOLERANCE_MM.lo:g} to {TOLERANCE_MM.hi:g}); default 1/25 of the in-spec depth "
        "tolerance (0.5 mm)",
        callback=within(TOLERANCE_MM),
    ),
]
AngleTolOpt = Annotated[
    float | None,
    typer.Option(
        "--angle-tol",
        metavar="DEG",
        help="how far its orientation may turn from a planned pose's, degrees (> 0, at most "
        "180); default 1/30 of the in-spec angle tolerance (0.5 deg)",
        callback=within(ANGLE_DEG),
    ),
]
ScanOutputOpt = Annotated[
    str | None,
    typer.Option(
        "--scan-output",
        help="the output switched on over each pass for the sensor's acquisition: URScript "
        "standard digital output 0-7 (default 0), KRL $OUT number (default 1), RAPID signal "
        "name (default doScan)",
    ),
]
RosFrameOpt = Annotated[
    str | None,
    typer.Option(
        "--ros-frame",
        help="ROS 2 YAML and rosbag2: the part's frame the targets are given in (default "
        "scan_part); a static transform from base_link (the part pose) places it, another "
        "from tool0 the TCP",
    ),
]
AllowUnreachableOpt = Annotated[
    bool,
    typer.Option(
        "--allow-unreachable",
        help="write the program even if the arm cannot fly it (unreachable poses, joint "
        "limits, configuration flips in a pass or the move into it, links or sensor in "
        "the part, table or fixtures); the problems are still printed",
    ),
]


@user_errors
def export_cmd(
    trajectory: TrajectoryArg,
    output: ProgramOutOpt,
    robot: ReachRobotOpt = None,
    fmt: FormatOpt = None,
    tcp: TcpOpt = None,
    part_pose: PartPoseOpt = None,
    profile_rate: ProfileRateOpt = None,
    spacing: SpacingOpt = None,
    travel_speed: TravelSpeedOpt = None,
    chord_tol: ChordTolOpt = None,
    angle_tol: AngleTolOpt = None,
    scan_output: ScanOutputOpt = None,
    ros_frame: RosFrameOpt = None,
    allow_unreachable: AllowUnreachableOpt = False,
    part: PlannedPartOpt = None,
    units: PlannedUnitsOpt = None,
    quiet: QuietOpt = False,
):
    """Write a robot program (URScript, ABB RAPID, KUKA KRL, ROS 2 YAML or bag, or CSV) once
    the arm is shown to fly it: nothing is written if a pose is unreachable, beyond the
    joint limits, flips configuration within a pass, puts an arm link within reach of the
    part, table or fixtures, or the sensor into them (unless --allow-unreachable). The arm,
    part pose and TCP default to those a plan made with --robot records; the sensor,
    spacing and speeds to the plan's; the language to the arm's controller."""
    # Deferred: the exporters and kinematics load scipy, yaml and FCL, which --help need not.
    from scanplan.core.plan import read_plan
    from scanplan.jobs.export import ProgramRequest, export_plan

    if output.exists() and output.resolve() == trajectory.resolve():
        raise ValueError(f"-o {output} is the plan being exported: give the program another name")
    plan = read_plan(trajectory)
    request = ProgramRequest(
        output, fmt, robot, tcp, part_pose, profile_rate, spacing, travel_speed, chord_tol,
        angle_tol, scan_output, ros_frame, allow_unreachable, part, units,
    )  # fmt: skip

    def say(text: str) -> None:
        typer.echo(text, err=text.startswith("warning:"))

    export_plan(plan, request, say, lambda label: progress_bar(label, quiet))


# ---- place --------------------------------------------------------------------------------
PlaceRobotOpt = Annotated[
    str,
    typer.Option(
        metavar="ARM",
        help="ur3e, ur5e, ur10e, kr6-r900, irb2400, lrmate200id or a TOML file of the arm's "
        "kinematics",
    ),
]
HeightRangeOpt = Annotated[
    str | None,
    typer.Option(
        "--height-range",
        metavar="LO,HI",
        help="heights (mm) the part's origin may take in the robot's base frame",
    ),
]
YawStepOpt = Annotated[
    float,
    typer.Option(
        "--yaw-step",
        metavar="DEG",
        help="step of the coarse search over the part's rotation about the vertical, degrees, "
        "(0, 360]",
        callback=bounded(0, 360, lo_open=True),
    ),
]


def parse_height_range(text: str | None) -> tuple[float, float] | None:
    """--height-range LO,HI in mm (None when not given: the search picks the heights)."""
    if text is None:
        return None
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"--height-range {text!r}: expected LO,HI in mm") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise ValueError(f"--height-range {text!r}: expected finite LO <= HI in mm")
    for v in (lo, hi):
        SIGNED_LENGTH_MM.check(v, "--height-range")
    return (lo, hi)


@user_errors
def place_cmd(
    trajectory: TrajectoryArg,
    robot: PlaceRobotOpt,
    tcp: TcpOpt = None,
    height_range: HeightRangeOpt = None,
    yaw_step: YawStepOpt = PLACE_YAW_STEP_DEG,
    part: PlannedPartOpt = None,
    units: PlannedUnitsOpt = None,
    quiet: QuietOpt = False,
):
    """Search the part's pose on the table (x, y, z, yaw) from which the arm reaches every
    pose with no configuration flip in a pass, its links clear of the part, the table and
    the fixtures (the arm stands beside the table); print it as --part-pose. A plan made for
    this arm (and --tcp not given, or the plan's) keeps its own placement if the arm flies
    every pose from there, as export checks it (with its turntable or track, if it has
    them; the search is for the arm alone, so such a plan is not searched again). Exit 2 if
    none does."""
    # Deferred: the placement search loads the kinematics and FCL, which --help need not.
    from scanplan.core.plan import read_plan
    from scanplan.jobs.place import place_plan, placement_lines

    heights = parse_height_range(height_range)
    plan = read_plan(trajectory)
    notes: list[str] = []
    result = place_plan(
        plan, robot, tcp, heights, yaw_step, part, units, notes.append,
        lambda label: progress_bar(label, quiet),
    )  # fmt: skip
    lines = placement_lines(result)
    for line in lines[:-1] + notes + lines[-1:]:
        typer.echo(line)
    if not result.flyable:
        typer.echo(
            "error: no placement flies every pose with the links clear "
            f"(best found above: {result.binding()})",
            err=True,
        )
        raise typer.Exit(2)
