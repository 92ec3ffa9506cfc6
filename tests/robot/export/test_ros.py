"""ROS 2 YAML: a PoseArray and a Path with planned arrival stamps, in the part's frame, and the
static transforms that place the part and the TCP."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from helpers import EXPORT_OPTIONS as OPTIONS
from helpers import rot_err, snake_trajectory
from scanplan.robot.export import ExportOptions, export_program, parse_program_details
from scanplan.robot.export.common import plan_motion
from scanplan.robot.export.ros import matrix_of
from scanplan.robot.export.rotations import parse_pose_arg

TRAJ = snake_trajectory()


def test_ros_structure() -> None:
    text = export_program(TRAJ, "ros", OPTIONS)
    doc = yaml.safe_load(text)
    assert doc["pose_array"]["header"]["frame_id"] == "scan_part"
    assert {p["header"]["frame_id"] for p in doc["path"]["poses"]} == {"scan_part"}
    motion = plan_motion(TRAJ, OPTIONS)  # the thinned targets, as every dialect writes
    assert len(doc["pose_array"]["poses"]) == len(doc["path"]["poses"]) == len(motion.poses)
    first = doc["pose_array"]["poses"][0]
    # In the part's frame: T_part_tcp, the part pose nowhere in the targets.
    np.testing.assert_allclose(
        [first["position"][k] for k in "xyz"],
        (TRAJ.poses[0] @ OPTIONS.scan.T_sensor_line)[:3, 3] / 1000,
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


def _transforms(doc: dict) -> dict[tuple[str, str], np.ndarray]:
    return {
        (t["header"]["frame_id"], t["child_frame_id"]): matrix_of(
            t["transform"]["translation"], t["transform"]["rotation"]
        )
        for t in doc["tf_static"]["transforms"]
    }


def test_ros_static_transforms_place_the_part_and_the_tcp() -> None:
    doc = yaml.safe_load(export_program(TRAJ, "ros", OPTIONS))
    tf = _transforms(doc)
    assert set(tf) == {("base_link", "scan_part"), ("tool0", "scan_tcp")}
    np.testing.assert_allclose(tf["base_link", "scan_part"], OPTIONS.part_pose, atol=1e-6)
    np.testing.assert_allclose(tf["tool0", "scan_tcp"], OPTIONS.tool, atol=1e-6)
    # Read back as T_base_sensor, as every dialect's parser.
    kept = plan_motion(TRAJ, OPTIONS).source
    parsed = parse_program_details(export_program(TRAJ, "ros", OPTIONS), "ros").poses
    expected = OPTIONS.part_pose @ TRAJ.poses[kept]
    assert np.abs(parsed[:, :3, 3] - expected[:, :3, 3]).max() < 1e-5
    assert rot_err(parsed, expected).max() < 1e-8


def test_moving_the_part_changes_one_transform() -> None:
    moved = ExportOptions(
        part_pose=parse_pose_arg("-300,250,40,75,0,0"),
        tcp=OPTIONS.tcp,
        scan=OPTIONS.scan,
        blend_mm=OPTIONS.blend_mm,
        ros_frame_id="door",
    )
    a, b = (yaml.safe_load(export_program(TRAJ, "ros", o)) for o in (OPTIONS, moved))
    assert a["pose_array"]["poses"] == b["pose_array"]["poses"]
    assert a["path"]["poses"][5]["pose"] == b["path"]["poses"][5]["pose"]
    assert b["path"]["header"]["frame_id"] == "door"
    tf = _transforms(b)
    np.testing.assert_allclose(tf["base_link", "door"], moved.part_pose, atol=1e-6)
    np.testing.assert_allclose(tf["tool0", "scan_tcp"], _transforms(a)["tool0", "scan_tcp"])


def test_ros_frames_are_checked() -> None:
    with pytest.raises(ValueError, match="ROS frames must differ"):
        ExportOptions(ros_frame_id="base_link")
    with pytest.raises(ValueError, match="ROS frame 'my part'"):
        ExportOptions(ros_frame_id="my part")
