"""The ROS 2 bag (export.rosbag): read back with rosbags' own reader, replaced only when it is a
bag, nothing left behind by a failed write."""

from __future__ import annotations

import errno
import sqlite3

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from helpers import EXPORT_OPTIONS as OPTIONS
from helpers import listing, rot_err, run_cli, snake_trajectory
from scanplan.core.plan_file import write_csv
from scanplan.core.trajectory import Trajectory
from scanplan.robot.export import (
    ExportOptions,
    export_program,
)
from scanplan.robot.export.common import plan_motion

TRAJ = snake_trajectory()


def _bag_messages(path) -> dict[str, tuple[str, int, object]]:
    """{topic: (msgtype, message count, the message)} read with rosbags' own Reader."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    out = {}
    with Reader(path) as reader:
        assert reader.message_count == 3
        for conn, timestamp, raw in reader.messages():
            assert timestamp == 0 and conn.topic not in out
            out[conn.topic] = (
                conn.msgtype,
                conn.msgcount,
                store.deserialize_cdr(raw, conn.msgtype),
            )
    return out


def test_rosbag_round_trip(tmp_path) -> None:
    from scanplan.robot.export import export_rosbag
    from scanplan.robot.export.rosbag import read_rosbag

    bag = tmp_path / "scan_bag"
    export_rosbag(TRAJ, bag, OPTIONS)
    assert listing(tmp_path) == ["scan_bag"]  # no staging directory left beside it
    assert listing(bag) == ["metadata.yaml", "scan_bag.db3"]
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 8 and meta["storage_identifier"] == "sqlite3"

    msgs = _bag_messages(bag)
    assert set(msgs) == {"/scanplan/path", "/scanplan/poses", "/tf_static"}
    path_type, path_count, path = msgs["/scanplan/path"]
    poses_type, poses_count, pose_array = msgs["/scanplan/poses"]
    assert (path_type, poses_type) == ("nav_msgs/msg/Path", "geometry_msgs/msg/PoseArray")
    assert path_count == poses_count == 1
    assert pose_array.header.frame_id == path.header.frame_id == "scan_part"
    motion = plan_motion(TRAJ, OPTIONS)  # the thinned targets, as every dialect writes
    assert len(pose_array.poses) == len(path.poses) == len(motion.poses)

    expected = motion.poses_part  # in the part's frame
    for poses in (pose_array.poses, [p.pose for p in path.poses]):
        xyz = np.array([[p.position.x, p.position.y, p.position.z] for p in poses])
        xyzw = np.array([[p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w]
                         for p in poses])  # fmt: skip
        assert np.abs(xyz - expected[:, :3, 3] / 1000).max() <= 1e-9
        R = Rotation.from_quat(xyzw).as_matrix()
        assert np.abs(R - expected[:, :3, :3]).max() <= 1e-9
        assert np.all(xyzw[:, 3] >= 0)  # the same canonical sign as the YAML export

    # Path stamps: the YAML export's planned arrival times, to the nanosecond.
    doc = yaml.safe_load(export_program(TRAJ, "ros", OPTIONS))
    yaml_stamps = [
        (s["sec"], s["nanosec"]) for s in (p["header"]["stamp"] for p in doc["path"]["poses"])
    ]
    bag_stamps = [(p.header.stamp.sec, p.header.stamp.nanosec) for p in path.poses]
    assert bag_stamps == yaml_stamps
    assert bag_stamps[-1][0] > 0  # the path takes seconds: the stamps are not all zero
    assert {p.header.frame_id for p in path.poses} == {"scan_part"}
    # The static transforms: the part in the base frame, the TCP on the flange.
    tf_type, _, tf = msgs["/tf_static"]
    assert tf_type == "tf2_msgs/msg/TFMessage"
    frames = [(t.header.frame_id, t.child_frame_id) for t in tf.transforms]
    assert frames == [("base_link", "scan_part"), ("tool0", "scan_tcp")]

    # Read back as the sensor's poses: the TCP's standoff undone.
    contents = read_rosbag(bag)
    sensor = OPTIONS.part_pose @ TRAJ.poses[motion.source]
    assert np.abs(contents.poses[:, :3, 3] - sensor[:, :3, 3]).max() <= 1e-6  # mm: 1e-9 m
    assert rot_err(contents.poses, sensor).max() < 1e-9
    np.testing.assert_array_equal(contents.scanning, motion.scanning)
    np.testing.assert_array_equal(contents.swath, motion.swath)
    np.testing.assert_array_equal(contents.speed_mm_s, motion.speed_mm_s)
    assert contents.frame_id == "scan_part"
    (_, _, part), (_, _, tool) = contents.transforms
    np.testing.assert_allclose(part, OPTIONS.part_pose, atol=1e-6)
    np.testing.assert_allclose(tool, OPTIONS.tool, atol=1e-6)
    assert contents.topics == {
        "/scanplan/path": path_type,
        "/scanplan/poses": poses_type,
        "/tf_static": tf_type,
    }
    assert contents.message_counts == {"/scanplan/path": 1, "/scanplan/poses": 1, "/tf_static": 1}
    # /tf_static offered as a static broadcaster does: late listeners still get it.
    meta_topics = {
        t["topic_metadata"]["name"]: t["topic_metadata"] for t in meta["topics_with_message_count"]
    }
    assert "durability: 1" in meta_topics["/tf_static"]["offered_qos_profiles"]


def test_rosbag_frame_id_and_replacing(tmp_path) -> None:
    from scanplan.robot.export import export_rosbag
    from scanplan.robot.export.rosbag import read_rosbag

    bag = tmp_path / "bag"
    export_rosbag(TRAJ, bag, OPTIONS)
    # A second export replaces the bag, as the text formats overwrite their file.
    short = Trajectory(TRAJ.poses[:5], TRAJ.swath[:5], TRAJ.scanning[:5])
    export_rosbag(short, bag, ExportOptions(ros_frame_id="world"))
    contents = read_rosbag(bag)
    kept = plan_motion(short, ExportOptions()).source  # the pass's start, end and a corner
    assert len(contents.poses) == len(kept) == 3 and contents.frame_id == "world"
    np.testing.assert_allclose(contents.poses, short.poses[kept], atol=1e-6)
    assert listing(tmp_path) == ["bag"] and listing(bag) == ["bag.db3", "metadata.yaml"]


def test_rosbag_refuses_to_replace_other_things(tmp_path) -> None:
    from scanplan.robot.export import export_rosbag

    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "keep.txt").write_text("mine")
    (tmp_path / "file").write_text("also mine")
    for name in ("notes", "file"):
        with pytest.raises(ValueError, match="not a rosbag2 directory"):
            export_rosbag(TRAJ, tmp_path / name, OPTIONS)
    assert (tmp_path / "notes" / "keep.txt").read_text() == "mine"
    assert (tmp_path / "file").read_text() == "also mine"
    assert listing(tmp_path) == ["file", "notes"]


def test_rosbag_failure_mid_write_leaves_nothing(tmp_path, monkeypatch) -> None:
    from rosbags.rosbag2 import Writer

    from scanplan.robot.export import export_rosbag
    from scanplan.robot.export.rosbag import read_rosbag

    bag = tmp_path / "bag"
    export_rosbag(Trajectory(TRAJ.poses[:3], [0, 0, 0], [True] * 3), bag, OPTIONS)
    real_write = Writer.write
    calls = []

    def failing_write(self, connection, timestamp, data):
        calls.append(connection.topic)
        if connection.topic == "/scanplan/poses":  # the second message of each bag
            raise OSError("No space left on device")
        real_write(self, connection, timestamp, data)

    monkeypatch.setattr(Writer, "write", failing_write)
    with pytest.raises(OSError, match="No space"):
        export_rosbag(TRAJ, tmp_path / "new_bag", OPTIONS)
    with pytest.raises(OSError, match="No space"):
        export_rosbag(TRAJ, bag, OPTIONS)
    assert len(calls) == 4
    assert listing(tmp_path) == ["bag"]  # no new bag, no staging directory
    assert len(read_rosbag(bag).poses) == 3  # the old bag is intact


@pytest.mark.parametrize(
    "failure, said",
    [
        (sqlite3.OperationalError("database or disk is full"), "database or disk is full"),
        (OSError(errno.ENOSPC, "No space left on device"), "No space left on device"),
    ],
    ids=["sqlite", "oserror"],
)
def test_rosbag_on_a_full_disk_is_one_line_exit_2_and_nothing_left(
    tmp_path, monkeypatch, failure, said
):
    from rosbags.rosbag2 import Writer

    def full(self, connection, timestamp, data):
        raise failure

    monkeypatch.setattr(Writer, "write", full)
    plan = tmp_path / "plan.csv"
    write_csv(TRAJ, plan)
    bag = tmp_path / "bag"
    result = run_cli("export", str(plan), "-o", str(bag), "--format", "rosbag2", "--robot", "none")
    assert result.exit_code == 2, result.output
    errors = [line for line in result.stderr.splitlines() if line.startswith("error")]
    assert errors == [f"error: cannot write rosbag2 {bag}: {said}"]
    assert "internal error" not in result.stderr
    assert listing(tmp_path) == ["plan.csv"]
