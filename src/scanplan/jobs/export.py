"""`export`: a plan as the robot program its arm runs, written once the arm is shown to fly
it. The program's language follows the arm (or the file name), its tool and speeds the
plan's sensor and ScanSpec, its cycle time the one `plan` printed.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from scanplan.core.files import atomic_write_text
from scanplan.core.limits import MAX_SCAN_SPEED_MM_S, POSITION_MM, TCP_MM
from scanplan.core.plan import Plan
from scanplan.jobs.planned import ProgressBar, Say, no_bar, plan_cell, planned_part
from scanplan.robot import get_robot
from scanplan.robot.axes import with_disk
from scanplan.robot.export import (
    FORMATS,
    ExportOptions,
    export_program,
    export_rosbag,
    parse_pose_arg,
    plan_motion,
)
from scanplan.robot.export.rotations import IDENTITY_POSE
from scanplan.robot.flyable import check_flyable
from scanplan.robot.program import axes_of, program_cycle, program_format
from scanplan.world.part import Part

# Why a program with joint jumps or near-singular poses is still written: it is flyable.
FLYABLE_ANYWAY = (
    " — the plan is still flyable (every target reachable within the joint limits, links "
    "clear); a jump is a fast joint move between two targets and a near-singular pose a "
    "slow one: check the speed on the cell"
)


@dataclass(frozen=True)
class ProgramRequest:
    """What the user asks of the program; None: as the plan records it (its arm, part pose,
    TCP, ScanSpec) or each dialect's default."""

    output: Path
    fmt: str | None = None
    robot: str | None = None
    tcp: str | None = None
    part_pose: str | None = None
    profile_rate_hz: float | None = None
    spacing_mm: float | None = None
    travel_speed_mm_s: float | None = None
    chord_tol_mm: float | None = None
    angle_tol_deg: float | None = None
    scan_output: str | None = None
    ros_frame: str | None = None
    allow_unreachable: bool = False
    part: str | None = None
    units: str | None = None


def arm_of(
    plan: Plan,
    robot: str | None,
    part_pose: str | None,
    tcp: str | None,
    say: Say,
) -> tuple[str, np.ndarray, np.ndarray]:
    """(robot, T_base_part, T_flange_sensor) from the options, else from the arm the plan was
    made for (said); --robot is required for a plan made for none, and a pose not given
    there is the identity (said)."""
    recorded = plan.arm
    if robot is None:
        if recorded is None:
            raise ValueError(
                "--robot is required: the arm to check the program on (ur3e, ur5e, ur10e, "
                "kr6-r900, irb2400, lrmate200id or a TOML file), or none to skip the check"
            )
        robot = recorded.robot
        say(f"--robot {robot} (the plan's)")
    same_arm = recorded is not None and robot == recorded.robot
    poses = []
    for option, value, key, meaning, position in (
        ("--part-pose", part_pose, "part_pose", "the part frame is the base", POSITION_MM),
        ("--tcp", tcp, "tcp", "the sensor origin is the flange", TCP_MM),
    ):
        if value is not None:
            poses.append(parse_pose_arg(value, position))
        elif same_arm and recorded is not None:
            say(f"{option} {recorded.record.get(key, '')} (the plan's)")
            poses.append(recorded.T_base_part if key == "part_pose" else recorded.T_flange_sensor)
        else:
            say(f"{option} not given: {IDENTITY_POSE} ({meaning})")
            poses.append(parse_pose_arg(IDENTITY_POSE))
    return robot, poses[0], poses[1]


def program_spec_options(plan: Plan, req: ProgramRequest, say: Say) -> ExportOptions:
    """The plan's ScanSpec (sensor, spacing, rates) with what the request overrides, said."""
    spec = plan.spec
    rate = spec.profile_rate_hz if req.profile_rate_hz is None else req.profile_rate_hz
    spacing = spec.delta_s_opt_mm if req.spacing_mm is None else req.spacing_mm
    travel = spec.travel_speed_mm_s if req.travel_speed_mm_s is None else req.travel_speed_mm_s
    changed = [
        f"{option} {value:g} (planned: {planned:g})"
        for option, value, planned in (
            ("--profile-rate", rate, spec.profile_rate_hz),
            ("--spacing", spacing, spec.delta_s_opt_mm),
            ("--travel-speed", travel, spec.travel_speed_mm_s),
        )
        if value != planned
    ]
    spec = replace(spec, profile_rate_hz=rate, delta_s_opt_mm=spacing, travel_speed_mm_s=travel)
    if spec.profile_rate_hz * spec.delta_s_opt_mm > MAX_SCAN_SPEED_MM_S:
        raise ValueError(
            f"profile rate {spec.profile_rate_hz:g} Hz x spacing {spec.delta_s_opt_mm:g} mm: "
            f"a scan speed of {spec.profile_rate_hz * spec.delta_s_opt_mm:g} mm/s, more than "
            f"the {MAX_SCAN_SPEED_MM_S:g} allowed"
        )
    if changed:
        say("note: the program differs from the plan: " + "; ".join(changed))
    return ExportOptions(scan=spec)


def export_plan(plan: Plan, req: ProgramRequest, say: Say, bar: ProgressBar = no_bar) -> None:
    """Write the program `req` asks for, once the arm is shown to fly it (nothing is written
    otherwise, unless `allow_unreachable`), and say what was written and its cycle time."""
    output = req.output
    program_format(req.fmt, output, None)  # an unknown --format is named before the arm
    robot, T_base_part, T_flange_sensor = arm_of(plan, req.robot, req.part_pose, req.tcp, say)
    fmt = program_format(req.fmt, output, robot)
    if fmt in FORMATS and (str(output) in ("", ".") or output.is_dir()):
        raise ValueError(f"-o {str(output)!r} is a directory: give the program's file name")
    # KUKA wants the .src file named after its DEF.
    name = output.stem if output.stem.isidentifier() and len(output.stem) <= 24 else ""
    options = replace(
        program_spec_options(plan, req, say),
        part_pose=T_base_part,
        tcp=T_flange_sensor,
        program_name=name if name and fmt == "krl" else "scanplan_path",
        chord_tol_mm=req.chord_tol_mm,
        angle_tol_deg=req.angle_tol_deg,
        scan_output=req.scan_output,
        axes=axes_of(plan),
    )
    if options.axes is not None:
        say(f"external axes: {options.axes.describe()} (the plan's, values per pose)")
    if req.ros_frame is not None:
        options = replace(options, ros_frame_id=req.ros_frame)
    motion = plan_motion(plan.traj, options)  # refuse an unexportable plan before the reach check
    none = robot.lower() == "none"
    if none:
        say("--robot none: no reach check; the program is not known to be flyable")
    else:
        arm = get_robot(robot)  # a bad arm is named before a missing part
        part = planned_part(
            plan, req.part, req.units, "the arm's links are checked against the part",
            other_part=req.part is not None, say=say,
        )  # fmt: skip
        joints = flyable_joints(plan, options, robot, req.allow_unreachable, part, say, bar)
        # Each pass entered by a joint move, in the configuration the arm's terms name.
        options = replace(options, joints_rad=joints, arm=arm)
    if fmt in FORMATS:
        atomic_write_text(output, export_program(plan.traj, fmt, options))
    else:
        export_rosbag(plan.traj, output, options)
    say(
        f"{fmt}: {len(motion.poses)} targets from {motion.n_planned} planned poses, "
        f"scan speed {options.scan_speed:.1f} mm/s -> {output}"
    )
    cycle = program_cycle(plan, options, robot=robot)
    say(cycle.line() + (", --robot none: timed on a nominal arm" if none else ""))
    if (planned := plan.cycle_time_s) is not None and abs(planned - cycle.total_s) >= 0.05:
        say(
            f"note: the plan's cycle time was {planned:.1f} s; this program's differs as its "
            "options differ from the plan's (arm, part pose, TCP, speeds or tolerances)"
        )


def flyable_joints(
    plan: Plan,
    options: ExportOptions,
    robot: str,
    allow: bool,
    part: Part,
    say: Say,
    bar: ProgressBar = no_bar,
) -> np.ndarray:
    """Whether `robot` flies every flange pose: reach, joint limits, configuration flips,
    and the arm's links and the sensor body against the part and its cell. Says the
    summaries; if the arm cannot fly the plan, a ValueError naming the first offending pass
    and pose (nothing is written), or with `allow` a warning. Returns the joint angles the
    check followed (n, 6), NaN where it found none."""
    with bar("reach and collision check"):
        result = check_flyable(
            plan.traj, get_robot(robot), options.part_pose, options.tcp, part,
            with_disk(plan_cell(plan, part), options.axes), plan.spec.sensor, axes=options.axes,
            entries=None if plan.arm is None else plan.arm.entry_joints(
                robot, options.part_pose, options.tcp
            ),
        )  # fmt: skip
    report = result.reach
    if result.flyable:
        warn = not report.ok  # near-singular poses or joint jumps: flyable, but say so
        say(("warning: " if warn else "") + report.summary() + (FLYABLE_ANYWAY if warn else ""))
        say(result.links.summary())
        say(result.sensor_summary())
        return report.joints
    where = result.first_problem(plan.traj.swath)
    if not allow:
        raise ValueError(
            f"{report.model} cannot fly this plan: {where} — place the part "
            "(scanplan place) or give --allow-unreachable"
        )
    # What passed is said too: the warning's summaries are those of what failed.
    for line, passed in (
        (report.summary(), report.reachable),
        (result.links.summary(), result.links.clear),
        (result.sensor_summary(), result.sensor_clear),
    ):
        if passed:
            say(line)
    say(f"warning: {where}")
    return report.joints
