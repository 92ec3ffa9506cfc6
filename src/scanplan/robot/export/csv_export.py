"""Base-frame CSV: the trajectory CSV's columns in the robot base frame, plus speed and blend.

Columns `swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz,speed_mm_s,blend_mm,standoff_mm` (then
`e1,..` the external axes' values, degrees or mm, where a plan has them); each row
is T_base_tcp (part_pose @ T_part_tcp), the TCP where the laser line meets the part at the
working distance: the sensor's pose moved `standoff_mm` along its beam (z). Speed is that of
the move ending at the row. For controllers or tools without a dedicated dialect here.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from scanplan.core.plan_file import CSV_COLUMNS, external_columns
from scanplan.robot.export.common import (
    ExportOptions,
    Motion,
    Parsed,
    sensor_poses,
)
from scanplan.robot.export.rotations import poses_from_parts, quat_wxyz

SUFFIX = ".csv"
COLUMNS = (*CSV_COLUMNS, "speed_mm_s", "blend_mm", "standoff_mm")


def write(motion: Motion, options: ExportOptions) -> str:
    q = quat_wxyz(motion.poses[:, :3, :3])
    p = motion.poses[:, :3, 3]
    ext = motion.external
    k = 0 if ext is None else ext.shape[1]
    lines = [",".join((*COLUMNS, *external_columns(k)))]
    for i in range(len(p)):
        lines.append(
            f"{motion.swath[i]},{int(motion.scanning[i])},"
            + ",".join(f"{v:.6f}" for v in p[i])
            + ","
            + ",".join(f"{v:.9f}" for v in q[i])
            + f",{motion.speed_mm_s[i]:.6f},{motion.blend_mm[i]:.6f},{motion.standoff_mm:.9g}"
            + ("" if ext is None else "".join(f",{v:.6f}" for v in ext[i]))
        )
    return "\n".join(lines) + "\n"


def parse(text: str) -> Parsed:
    rows = [r for r in text.splitlines() if r.strip()]
    header = tuple(c.strip() for c in rows[0].split(",")) if rows else ()
    k = len(header) - len(COLUMNS)
    if header[: len(COLUMNS)] != COLUMNS or header[len(COLUMNS) :] != external_columns(k):
        raise ValueError(f"base-frame CSV must start with the header {','.join(COLUMNS)}")
    try:
        arr = np.array([[float(c) for c in r.split(",")] for r in rows[1:]])
        arr = arr.reshape(-1, len(header))
    except ValueError as exc:
        raise ValueError(f"base-frame CSV: {exc}") from None
    rot = Rotation.from_quat(np.concatenate([arr[:, 6:9], arr[:, 5:6]], axis=1))
    poses = sensor_poses(poses_from_parts(arr[:, 2:5], rot), arr[:, 11])
    external = arr[:, len(COLUMNS) :] if k else None
    return Parsed(poses, arr[:, 1] > 0.5, arr[:, 9], arr[:, 10] > 0, external)
