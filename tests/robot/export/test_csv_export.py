"""The base-frame CSV: its header and frame (the TCP at the laser line)."""

from __future__ import annotations

import numpy as np

from helpers import snake_trajectory
from scanplan.robot.export import (
    ExportOptions,
    export_program,
    parse_pose_arg,
)

TRAJ = snake_trajectory()


def test_csv_header_and_frame() -> None:
    text = export_program(TRAJ, "csv", ExportOptions(part_pose=parse_pose_arg("10,20,30,0,0,0")))
    header, first = text.splitlines()[:2]
    assert header == "swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz,speed_mm_s,blend_mm,standoff_mm"
    cells = [float(c) for c in first.split(",")]
    # The row is the TCP: the laser line at the working distance, W_d along the sensor's z.
    wd = ExportOptions().scan.working_distance_mm
    line = TRAJ.positions_mm[0] + wd * TRAJ.poses[0, :3, 2]
    np.testing.assert_allclose(cells[2:5], line + [10, 20, 30], atol=1e-6)
    assert cells[11] == wd
