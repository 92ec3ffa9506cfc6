"""The base-frame CSV: its header and frame."""

from __future__ import annotations

import numpy as np

from helpers import snake_trajectory
from scanplan.export import (
    ExportOptions,
    export_program,
    parse_pose_arg,
)

TRAJ = snake_trajectory()


def test_csv_header_and_frame() -> None:
    text = export_program(TRAJ, "csv", ExportOptions(part_pose=parse_pose_arg("10,20,30,0,0,0")))
    header, first = text.splitlines()[:2]
    assert header == "swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz,speed_mm_s,blend_mm"
    cells = [float(c) for c in first.split(",")]
    np.testing.assert_allclose(cells[2:5], TRAJ.positions_mm[0] + [10, 20, 30], atol=1e-6)
