"""ROS 2 YAML: a PoseArray and a Path with planned arrival stamps."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from helpers import EXPORT_OPTIONS as OPTIONS
from helpers import snake_trajectory
from scanplan.export import export_program

TRAJ = snake_trajectory()


def test_ros_structure() -> None:
    text = export_program(TRAJ, "ros", OPTIONS)
    doc = yaml.safe_load(text)
    assert doc["pose_array"]["header"]["frame_id"] == "base_link"
    assert len(doc["pose_array"]["poses"]) == len(doc["path"]["poses"]) == len(TRAJ)
    first = doc["pose_array"]["poses"][0]
    np.testing.assert_allclose(
        [first["position"][k] for k in "xyz"],
        (OPTIONS.part_pose @ TRAJ.poses[0])[:3, 3] / 1000,
        atol=1e-9,
    )
    stamps = [p["header"]["stamp"] for p in doc["path"]["poses"]]
    t = np.array([s["sec"] + s["nanosec"] * 1e-9 for s in stamps])
    assert t[0] == 0 and np.all(np.diff(t) >= 0)
    # One scan step of 0.5 mm at 100 mm/s takes 5 ms.
    i = int(np.flatnonzero(TRAJ.scanning)[1])
    assert t[i] - t[i - 1] == pytest.approx(
        np.linalg.norm(np.diff(TRAJ.positions_mm[i - 1 : i + 1], axis=0)) / 100, abs=1e-8
    )
