"""Files the command-line suites share."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from scanplan.core.plan_file import write_csv
from scanplan.core.trajectory import Trajectory
from scanplan.planning.swaths import Swath


@pytest.fixture()
def plate_and_trajectory(tmp_path):
    """A 600 x 600 plate (top at z = 0) as STL, and 21 poses at W_d above it as CSV."""
    plate = trimesh.creation.box((600, 600, 10))
    plate.apply_translation((0, 0, -5))
    plate_path = tmp_path / "plate.stl"
    plate.export(plate_path)
    sw = Swath(0, np.array([-50.0, 0, 400]), np.array([50.0, 0, 400]), np.eye(3)[0], np.eye(3)[1])
    poses = sw.poses(np.linspace(0, 100, 21), np.zeros(21), np.zeros(21))
    traj_path = tmp_path / "t.csv"
    write_csv(Trajectory(poses, np.zeros(21, int), np.ones(21, bool)), traj_path)
    return plate_path, traj_path
