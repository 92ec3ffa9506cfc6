"""Robot programs from a trajectory: URScript, ABB RAPID, KUKA KRL, ROS 2 YAML, base-frame CSV,
and a ROS 2 bag (`rosbag2`, a directory rather than a text file: `export_rosbag`).

Every dialect writes the poses of the program's TCP, the laser line at the working distance
(`T_part_sensor @ ScanSpec.T_sensor_line`), under the part's pose, with the program's tool set
to that point (`ExportOptions.tool` = `T_flange_sensor @ T_sensor_line`); reading a program
back undoes the standoff its header records, so parsers return `T_base_sensor`.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from scanplan.core.trajectory import Trajectory
from scanplan.robot.export import csv_export, krl, rapid, ros, rosbag, urscript
from scanplan.robot.export.common import (
    ExportOptions,
    Motion,
    Parsed,
    flange_poses,
    plan_motion,
)
from scanplan.robot.export.rotations import parse_pose_arg

__all__ = [
    "DIRECTORY_FORMATS",
    "FORMATS",
    "Dialect",
    "ExportOptions",
    "Parsed",
    "export_program",
    "export_rosbag",
    "flange_poses",
    "parse_pose_arg",
    "parse_program",
    "parse_program_details",
]


@dataclass(frozen=True)
class Dialect:
    name: str
    suffix: str  # the file extension the controller expects
    write: Callable[[Motion, ExportOptions], str]
    parse: Callable[[str], Parsed]


FORMATS: dict[str, Dialect] = {
    name: Dialect(name, module.SUFFIX, module.write, module.parse)
    for name, module in (
        ("urscript", urscript),
        ("rapid", rapid),
        ("krl", krl),
        ("ros", ros),
        ("csv", csv_export),
    )
}


# Formats written as a directory by their own writer, not as text by `export_program`.
DIRECTORY_FORMATS = ("rosbag2",)


def _dialect(fmt: str) -> Dialect:
    try:
        return FORMATS[fmt]
    except KeyError:
        raise ValueError(
            f"unknown export format {fmt!r}; choose one of {', '.join(FORMATS)}"
            + (f" (or export_rosbag for {fmt})" if fmt in DIRECTORY_FORMATS else "")
        ) from None


def export_program(traj: Trajectory, fmt: str, options: ExportOptions | None = None) -> str:
    """The program text for `fmt`; the caller writes it (with `atomic_write_text`)."""
    dialect = _dialect(fmt)
    options = options or ExportOptions()
    return dialect.write(plan_motion(traj, options), options)


def export_rosbag(
    traj: Trajectory, path: str | os.PathLike, options: ExportOptions | None = None
) -> None:
    """Write the ROS 2 YAML export's messages as the rosbag2 directory `path` (atomically)."""
    options = options or ExportOptions()
    if options.axes is not None:
        raise ValueError(
            "rosbag2 does not carry external axes yet: export the plan as ros (its YAML holds "
            "the axes' joint trajectory)"
        )
    rosbag.write_rosbag(plan_motion(traj, options), options, path)


def parse_program_details(text: str, fmt: str) -> Parsed:
    """Poses, scanning flags, speeds and blending read back from a program of `fmt`."""
    return _dialect(fmt).parse(text)


def parse_program(text: str, fmt: str) -> tuple[np.ndarray, np.ndarray]:
    """(poses (n, 4, 4) `T_base_sensor` in mm, scanning (n,) bool) read back from a program."""
    parsed = parse_program_details(text, fmt)
    return parsed.poses, parsed.scanning
