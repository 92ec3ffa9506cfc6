"""ROS 2 YAML: a PoseArray and a Path with planned arrival stamps."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from helpers import EXPORT_OPTIONS as OPTIONS
from helpers import snake_trajectory
from scanplan.export import export_program
from scanplan.export.common import plan_motion

TRAJ = snake_trajectory()


def test_ros_structure() -> None:
    text = export_program(TRAJ, "ros", OPTIONS)
    doc = yaml.safe_load(text)
    assert doc["pose_array"]["header"]["frame_id"] == "base_link"
    motion = plan_motion(TRAJ, OPTIONS)  # the thinned targets, as every dialect writes
    assert len(doc["pose_array"]["poses"]) == len(doc["path"]["poses"]) == len(motion.poses)
    first = doc["pose_array"]["poses"][0]
    np.testing.assert_allclose(
        [first["position"][k] for k in "xyz"],
        (OPTIONS.part_pose @ TRAJ.poses[0] @ OPTIONS.scan.T_sensor_line)[:3, 3] / 1000,
        atol=1e-9,
    )
    assert doc["scanplan"]["standoff_mm"] == 400.0
    stamps = [p["header"]["stamp"] for p in doc["path"]["poses"]]
    t = np.array([s["sec"] + s["nanosec"] * 1e-9 for s in stamps])
    assert t[0] == 0 and np.all(np.diff(t) >= 0)
    # A scanning move takes its length at 100 mm/s.
    i = int(np.flatnonzero(motion.scanning & ~motion.pass_start)[0])
    p = motion.poses[:, :3, 3]
    assert t[i] - t[i - 1] == pytest.approx(np.linalg.norm(p[i] - p[i - 1]) / 100, abs=1e-8)
