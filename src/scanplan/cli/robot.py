"""`scanplan export` and `place`: a trajectory as a robot program, and the part's pose on the
table from which an arm reaches all of it.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import numpy as np
import typer

from scanplan.cli.common import progress_bar, user_errors
from scanplan.cli.options import (
    IDENTITY_POSE,
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
from scanplan.core.quantities import ScanSpec

if TYPE_CHECKING:
    from scanplan.core.trajectory import Trajectory
    from scanplan.robot.export import ExportOptions
    from scanplan.world.cell import Cell
    from scanplan.world.part import Part

# ---- export -------------------------------------------------------------------------------
ROBOT_HELP = (
    "arm to check reach on: ur3e, ur5e, ur10e, kr6-r900, irb2400, lrmate200id or a TOML "
    "file of OPW parameters; 'none' to skip"
)
ProgramOutOpt = Annotated[
    Path, typer.Option("-o", "--output", help="output file (a directory for rosbag2)")
]
FormatOpt = Annotated[
    str, typer.Option("--format", help="urscript, rapid, krl, ros, rosbag2 or csv")
]
ProfileRateOpt = Annotated[
    float,
    typer.Option(
        help=f"sensor profile rate, Hz, {PROFILE_RATE_HZ.lo:g} to {PROFILE_RATE_HZ.hi:g}; scan "
        f"speed = rate x spacing, at most {MAX_SCAN_SPEED_MM_S:g} mm/s",
        callback=within(PROFILE_RATE_HZ),
    ),
]
SpacingOpt = Annotated[
    float,
    typer.Option(
        help=f"profile spacing on the part, mm, {STEP_MM.lo:g} to {STEP_MM.hi:g}",
        callback=within(STEP_MM),
    ),
]
TravelSpeedOpt = Annotated[
    float,
    typer.Option(
        help=f"speed between passes, mm/s, {SPEED_MM_S.lo:g} to {SPEED_MM_S.hi:g}",
        callback=within(SPEED_MM_S),
    ),
]
ReachRobotOpt = Annotated[
    str | None,
    typer.Option(help=ROBOT_HELP + "; default: the arm the plan was made for, if any"),
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
        "limits, configuration flips in a pass, links or sensor in the part, table or "
        "fixtures); the problems are still printed",
    ),
]


@user_errors
def export_cmd(
    trajectory: TrajectoryArg,
    output: ProgramOutOpt,
    robot: ReachRobotOpt = None,
    fmt: FormatOpt = "urscript",
    tcp: TcpOpt = None,
    part_pose: PartPoseOpt = None,
    profile_rate: ProfileRateOpt = ScanSpec.profile_rate_hz,
    spacing: SpacingOpt = ScanSpec.delta_s_opt_mm,
    travel_speed: TravelSpeedOpt = ScanSpec.travel_speed_mm_s,
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
    part pose and TCP default to those a plan made with --robot records."""
    # Deferred: the exporters and kinematics load numpy, scipy and yaml.
    from scanplan.core.files import atomic_write_text
    from scanplan.core.trajectory import read_trajectory
    from scanplan.robot.export import (
        DIRECTORY_FORMATS,
        FORMATS,
        ExportOptions,
        export_program,
        export_rosbag,
    )
    from scanplan.robot.export.common import plan_motion

    if fmt not in FORMATS and fmt not in DIRECTORY_FORMATS:
        choices = ", ".join([*FORMATS, *DIRECTORY_FORMATS])
        raise ValueError(f"unknown format {fmt!r}; use one of {choices}")
    if fmt in FORMATS and (str(output) in ("", ".") or output.is_dir()):
        raise ValueError(f"-o {str(output)!r} is a directory: give the program's file name")
    # KUKA wants the .src file named after its DEF.
    name = output.stem if output.stem.isidentifier() and len(output.stem) <= 24 else ""
    if output.exists() and output.resolve() == trajectory.resolve():
        raise ValueError(f"-o {output} is the plan being exported: give the program another name")
    if profile_rate * spacing > MAX_SCAN_SPEED_MM_S:  # each in range, their product not
        raise ValueError(
            f"--profile-rate {profile_rate:g} x --spacing {spacing:g}: a scan speed of "
            f"{profile_rate * spacing:g} mm/s, more than the {MAX_SCAN_SPEED_MM_S:g} allowed"
        )
    traj = read_trajectory(trajectory)
    robot, T_base_part, T_flange_sensor = arm_of(traj, robot, part_pose, tcp)
    options = ExportOptions(
        part_pose=T_base_part,
        tcp=T_flange_sensor,
        scan=ScanSpec(
            delta_s_opt_mm=spacing, profile_rate_hz=profile_rate, travel_speed_mm_s=travel_speed
        ),
        program_name=name if name and fmt == "krl" else "scanplan_path",
        chord_tol_mm=chord_tol,
        angle_tol_deg=angle_tol,
        scan_output=scan_output,
    )
    if ros_frame is not None:
        options = replace(options, ros_frame_id=ros_frame)
    motion = plan_motion(traj, options)  # refuse an unexportable plan before the reach check
    if robot.lower() == "none":
        typer.echo("--robot none: no reach check; the program is not known to be flyable")
    else:
        from scanplan.robot import get_robot  # deferred: as the exporters above

        get_robot(robot)  # a bad arm is named before a missing part
        cell = planned_cell(traj, part, units)
        joints = check_flyable(traj, options, robot, quiet, allow_unreachable, cell)
        # Each pass entered by a joint move, in the configuration the arm's terms name.
        options = replace(options, joints_rad=joints, arm=get_robot(robot))
    text = export_program(traj, fmt, options) if fmt in FORMATS else None
    if text is not None:
        atomic_write_text(output, text)
    else:
        export_rosbag(traj, output, options)
    typer.echo(
        f"{fmt}: {len(motion.poses)} targets from {motion.n_planned} planned poses, "
        f"scan speed {options.scan_speed:.1f} mm/s -> {output}"
    )
    # Deferred: as the exporters above.
    from scanplan.core.cycle import NOMINAL, cycle_time
    from scanplan.robot import motion_limits

    none = robot.lower() == "none"
    limits = NOMINAL if none else motion_limits(robot)
    # Planned again with the joints: a joint move into a pass starts from an exact stop.
    motion = plan_motion(traj, options)
    cycle = cycle_time(
        traj, options.scan, limits, options.joints_rad, motion.source, motion.blend_mm > 0
    )
    typer.echo(cycle.line() + (", --robot none: timed on a nominal arm" if none else ""))


def arm_of(
    traj: Trajectory,
    robot: str | None,
    part_pose: str | None,
    tcp: str | None,
    say_recorded: bool = True,
) -> tuple[str, np.ndarray, np.ndarray]:
    """(robot, T_base_part, T_flange_sensor) from the options, else from the arm the plan was
    made for (said in the output unless not `say_recorded`); --robot is required for a plan
    made for none, and a pose not given there is the identity (said)."""
    # Deferred: as in export_cmd.
    from scanplan.robot.export import parse_pose_arg

    recorded = traj.meta.get("robot") or {}
    if robot is None:
        if not recorded:
            raise ValueError(
                "--robot is required: the arm to check the program on (ur3e, ur5e, ur10e, "
                "kr6-r900, irb2400, lrmate200id or a TOML file), or none to skip the check"
            )
        robot = str(recorded["robot"])
        if say_recorded:
            typer.echo(f"--robot {robot} (the plan's)")
    poses = []
    for option, value, key, arg, meaning in (
        ("--part-pose", part_pose, "T_base_part", "part_pose", "the part frame is the base"),
        ("--tcp", tcp, "T_flange_sensor", "tcp", "the sensor origin is the flange"),
    ):
        if value is not None:
            poses.append(parse_pose_arg(value))
        elif key in recorded and robot == recorded.get("robot"):
            if say_recorded:
                typer.echo(f"{option} {recorded.get(arg, '')} (the plan's)")
            poses.append(np.asarray(recorded[key], dtype=np.float64))
        else:
            typer.echo(f"{option} not given: {IDENTITY_POSE} ({meaning})")
            poses.append(parse_pose_arg(IDENTITY_POSE))
    return robot, poses[0], poses[1]


def planned_cell(
    traj: Trajectory,
    part: str | None,
    units: str | None,
    needed_for: str = "the arm's links are checked against the part",
) -> tuple[Part, Cell]:
    """The part (--part, else the one the plan records) and the cell the plan was made in
    (its table and fixtures), which the arm's links and the sensor are checked against;
    `needed_for` says why in the error when there is no part."""
    # Deferred: the part loads trimesh (and cascadio for STEP).
    from scanplan.core.plan import recorded
    from scanplan.world.cell import planned_cell
    from scanplan.world.part import load_part

    context = recorded(traj, ScanSpec())
    name = part or context.part
    if not name:
        raise ValueError(
            f"--part is required: {needed_for}, and this plan records none (planned before "
            "plans named their part)"
        )
    the_part = load_part(name, units or context.fixture_units)
    return the_part, planned_cell(context, the_part)


def check_flyable(
    traj: Trajectory,
    options: ExportOptions,
    robot: str,
    quiet: bool,
    allow: bool,
    cell: tuple[Part, Cell],
) -> np.ndarray:
    """Whether `robot` flies every flange pose: reach, joint limits, configuration flips,
    and the arm's links and the sensor body against the part and its `cell`. Prints the
    summaries; if the arm cannot fly the plan, a ValueError naming the first offending pass
    and pose (nothing is written), or with `allow` a warning. Returns the joint angles the
    check followed (n, 6), NaN where it found none."""
    # Deferred: as in export_cmd.
    from scanplan.core.plan import recorded
    from scanplan.robot import get_robot
    from scanplan.robot.flyable import check_flyable as check

    part, the_cell = cell
    sensor = recorded(traj, ScanSpec()).spec.sensor
    with progress_bar("reach and collision check", quiet):
        result = check(
            traj, get_robot(robot), options.part_pose, options.tcp, part, the_cell, sensor
        )
    report = result.reach
    if result.flyable:
        warn = not report.ok  # near-singular poses or joint jumps: flyable, but say so
        typer.echo(("warning: " if warn else "") + report.summary(), err=warn)
        typer.echo(result.links.summary())
        return report.joints
    where = result.first_problem(traj.swath)
    if not allow:
        raise ValueError(
            f"{report.model} cannot fly this plan: {where} — place the part "
            "(scanplan place) or give --allow-unreachable"
        )
    typer.echo(f"warning: {where}", err=True)
    return report.joints


# ---- place --------------------------------------------------------------------------------
PlaceRobotOpt = Annotated[
    str, typer.Option(help="ur3e, ur5e, ur10e, kr6-r900, irb2400, lrmate200id or a TOML file")
]
HeightRangeOpt = Annotated[
    str | None,
    typer.Option("--height-range", help="LO,HI mm: the part origin's z in the base frame"),
]
YawStepOpt = Annotated[
    float,
    typer.Option(
        "--yaw-step", help="coarse yaw grid, deg, (0, 360]", callback=bounded(0, 360, lo_open=True)
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
    yaw_step: YawStepOpt = 30.0,
    part: PlannedPartOpt = None,
    units: PlannedUnitsOpt = None,
    quiet: QuietOpt = False,
):
    """Search the part's pose on the table (x, y, z, yaw) from which the arm reaches every
    pose with no configuration flip in a pass, its links clear of the part, the table and
    the fixtures (the arm stands beside the table); print it as --part-pose. Exit 2 if none
    does."""
    # Deferred: the placement search loads the kinematics (numpy, scipy).
    from scanplan.core.plan import recorded
    from scanplan.core.trajectory import read_trajectory
    from scanplan.robot import get_robot
    from scanplan.robot.export import parse_pose_arg
    from scanplan.robot.links import obstacles_for
    from scanplan.robot.place import place

    heights = parse_height_range(height_range)
    traj = read_trajectory(trajectory)
    arm = get_robot(robot)  # a bad arm is named before a missing part
    spec = recorded(traj, ScanSpec()).spec
    obstacles = obstacles_for(*planned_cell(traj, part, units), spec.sensor, spec.clearance_mm)
    with progress_bar("searching a placement", quiet):
        result = place(
            traj,
            arm,
            parse_pose_arg(tcp or IDENTITY_POSE),
            heights,
            yaw_step,
            obstacles=obstacles,
        )
    m = result.report.worst_margins()
    typer.echo(f"--part-pose {result.pose_arg()}")
    typer.echo(result.report.summary())
    if result.links is not None:
        typer.echo(result.links.summary())
    if tcp is None:
        typer.echo(f"--tcp not given: {IDENTITY_POSE} (the sensor origin is the flange)")
    typer.echo(
        f"worst margins: joint limit {m['limit_deg']:.1f} deg, wrist {m['wrist_deg']:.1f} deg, "
        f"elbow {m['elbow_deg']:.1f} deg, shoulder {m['shoulder_mm']:.0f} mm "
        f"({result.evaluated} placements in {result.seconds:.1f} s)"
    )
    if not result.flyable:
        typer.echo(
            "error: no placement flies every pose with the links clear "
            f"(best found above: {result.binding()})",
            err=True,
        )
        raise typer.Exit(2)
