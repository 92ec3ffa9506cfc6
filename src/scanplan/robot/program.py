"""The robot program a plan becomes: its dialect (from the arm, the file name or the user),
the export options it is written with (the plan's ScanSpec, arm, part pose and TCP), and
its cycle time. `plan`, `export` and `evaluate` all time a plan here, so they agree.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from scanplan.core.cycle import NOMINAL, CycleTime, MotionLimits, cycle_time
from scanplan.core.plan import Plan
from scanplan.core.trajectory import pass_entries
from scanplan.robot.axes import ExternalAxes, axes_seconds, part_poses, plan_axes
from scanplan.robot.export import DIRECTORY_FORMATS, FORMATS, ExportOptions, plan_motion
from scanplan.robot.presets import get_robot, motion_limits
from scanplan.robot.reach import check_reach

# The controller language each preset arm runs; a user's arm file names none, so its
# program's dialect comes from --format or the output's extension.
ARM_DIALECTS = {
    "ur3e": "urscript",
    "ur5e": "urscript",
    "ur10e": "urscript",
    "kr6-r900": "krl",
    "irb2400": "rapid",
}
# Dialects any arm's integrator can use: a motion-planning stack (ROS 2) or a table.
NEUTRAL_DIALECTS = ("ros", "rosbag2", "csv")
# The extension each dialect's file has (`--format` follows it when not given).
SUFFIX_DIALECTS = {d.suffix: name for name, d in FORMATS.items()} | {".urscript": "urscript"}


def program_format(fmt: str | None, output: Path, robot: str | None) -> str:
    """The dialect of the program for `robot` (None or 'none': no arm) written to `output`:
    `fmt` if given, else the output's extension, else the arm's language. ValueError (one
    line) for a dialect the arm's controller does not run (KRL for a UR arm), or an
    extension that names another dialect than the one written (URScript in a .src file)."""
    choices = ", ".join([*FORMATS, *DIRECTORY_FORMATS])
    if fmt is not None and fmt not in FORMATS and fmt not in DIRECTORY_FORMATS:
        raise ValueError(f"unknown format {fmt!r}; use one of {choices}")
    by_suffix = SUFFIX_DIALECTS.get(output.suffix.lower())
    arm = None if robot is None or robot.lower() == "none" else robot
    native = ARM_DIALECTS.get(arm.lower()) if arm is not None else None
    chosen = fmt or by_suffix or native
    if chosen is None:
        if arm is None:
            chosen = "csv"  # no arm: the base-frame table any tool reads
        else:
            raise ValueError(
                f"the program's language for arm {arm} is not known: give --format "
                f"({choices}) or an output file with its extension"
            )
    if by_suffix is not None and by_suffix != chosen and chosen not in DIRECTORY_FORMATS:
        raise ValueError(
            f"-o {output.name}: a {output.suffix} file holds {by_suffix}, not {chosen}: name "
            f"the file {output.stem}{FORMATS[chosen].suffix} or give --format {by_suffix}"
        )
    if native is not None and chosen != native and chosen not in NEUTRAL_DIALECTS:
        raise ValueError(
            f"{chosen} is not the language of {arm}'s controller ({native}): give "
            f"--format {native} (or ros or csv), or plan for the arm that runs {chosen}"
        )
    return chosen


def arm_joints(plan: Plan) -> np.ndarray | None:
    """(n, 6) the joints the plan's arm takes at each pose (the reach check's, NaN where it
    finds none); None for a plan made for no arm."""
    if plan.arm is None:
        return None
    arm = plan.arm
    try:
        robot = get_robot(arm.robot)
    except (ValueError, OSError):  # an arm file gone since: timed without its joints
        return None
    # As `flyable.check_flyable` computes them, so export's joints are these to the bit.
    T_base_part = part_poses(arm.T_base_part, plan.traj.external, axes_of(plan))
    T_base_flange = T_base_part @ plan.traj.poses @ np.linalg.inv(arm.T_flange_sensor)
    entries = arm.entry_joints(arm.robot, arm.T_base_part, arm.T_flange_sensor)
    report = check_reach(
        T_base_flange,
        robot,
        swath=plan.traj.swath,
        scanning=plan.traj.scanning,
        entries=entries,
        entry=pass_entries(plan.traj),
    )
    return report.joints


def arm_limits(robot: str | None) -> MotionLimits:
    """The motion limits a program is timed with: the arm's, else (no arm, or an arm file
    that is gone) the nominal arm's."""
    if robot is None or robot.lower() == "none":
        return NOMINAL
    try:
        return motion_limits(robot)
    except (ValueError, OSError):
        return NOMINAL


def program_options(plan: Plan) -> ExportOptions:
    """The export options a plan's program is written with by default: its ScanSpec (sensor,
    spacing, rates), and its arm's part pose and TCP (identity without an arm)."""
    options = ExportOptions(scan=plan.spec, axes=axes_of(plan))
    if plan.arm is not None:
        options = replace(options, part_pose=plan.arm.T_base_part, tcp=plan.arm.T_flange_sensor)
    return options


def axes_of(plan: Plan) -> ExternalAxes | None:
    """The external axes a plan was made with (`robot.axes.plan_axes`), None: the arm alone."""
    record = None if plan.arm is None else plan.arm.record
    return plan_axes(record, plan.traj.external, plan.where)


def program_cycle(
    plan: Plan,
    options: ExportOptions | None = None,
    joints_rad: np.ndarray | None = None,
    robot: str | None = None,
) -> CycleTime:
    """The cycle time of the program of `plan` written with `options` (None: the plan's own,
    `program_options`) on `robot` (None: the plan's arm), its passes entered by joint moves
    into `joints_rad` (None: the plan's arm's, `arm_joints`)."""
    options = program_options(plan) if options is None else options
    robot = robot if robot is not None else (plan.arm.robot if plan.arm is not None else None)
    if joints_rad is None and options.joints_rad is None:
        joints_rad = arm_joints(plan) if plan.arm is not None and robot == plan.arm.robot else None
    if joints_rad is not None:
        options = replace(options, joints_rad=joints_rad)
    # Planned with the joints: a joint move into a pass starts from an exact stop.
    motion = plan_motion(plan.traj, options)
    cycle = cycle_time(
        plan.traj,
        options.scan,
        arm_limits(robot),
        options.joints_rad,
        motion.source,
        motion.blend_mm > 0,
    )
    if options.axes is None:
        return cycle
    extra = axes_seconds(plan.traj, options.axes, options.scan, options.scan_speed)
    return replace(cycle, total_s=cycle.total_s + extra, axes_s=extra)
