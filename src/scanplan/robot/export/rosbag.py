"""ROS 2 bag: the ROS YAML export's two messages as a rosbag2 directory (pure Python).

Written with the `rosbags` package: sqlite3 storage (`<name>/<name>.db3` + `metadata.yaml`),
bag format version 8, CDR serialization, message definitions from the Humble typestore
(`Pose`, `PoseArray`, `Path` are unchanged up to Jazzy). Version 8 is the oldest `rosbags`
writes and keeps the topic QoS as the string Humble/Iron parse; Jazzy reads it too (a
version 9 bag, Jazzy's own, is not readable by Humble). sqlite3 is the default storage
plugin of stock Humble; Jazzy ships it beside mcap.

Three topics, one message each, all stamped 0 (the bag starts at the epoch, like the YAML's
headers): `/scanplan/path` (`nav_msgs/msg/Path`, pose stamps = planned arrival times from the
start), `/scanplan/poses` (`geometry_msgs/msg/PoseArray`) and `/tf_static`
(`tf2_msgs/msg/TFMessage`, transient local as a static broadcaster offers it: base -> part,
flange -> TCP). Poses are `T_<part frame>_tcp` (the TCP where the laser line meets the part at
the working distance) in metres, quaternion x, y, z, w, computed by `scanplan.robot.export.ros`, so
moving the part changes one transform. What no message holds — the scanning flags, swath
indices, speeds and the TCP's standoff from the sensor — goes into the metadata's
`custom_data`.

The bag is written into a hidden staging directory beside the target and renamed into place,
so a failure never leaves a half-written bag. An existing rosbag2 directory (one holding a
`metadata.yaml`) is replaced, as the other formats overwrite their file; any other existing
path is refused.
"""

from __future__ import annotations

import os
import shutil
import sqlite3
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from scanplan.core.files import cannot_write, replace_directory
from scanplan.robot.export.common import ExportOptions, Motion, sensor_poses
from scanplan.robot.export.ros import (
    arrival_times,
    base_poses,
    matrix_of,
    ros_poses,
    split_stamp,
    static_transforms,
)
from scanplan.robot.export.rotations import poses_from_parts

PATH_TOPIC = "/scanplan/path"
POSES_TOPIC = "/scanplan/poses"
PATH_TYPE = "nav_msgs/msg/Path"
POSES_TYPE = "geometry_msgs/msg/PoseArray"
TF_STATIC_TOPIC = "/tf_static"
TF_TYPE = "tf2_msgs/msg/TFMessage"
BAG_VERSION: Literal[8] = 8
_KEYS = ("scanning", "swath", "speed_mm_s")


def _typestore() -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _tf_qos() -> Any:
    """What tf2's StaticTransformBroadcaster offers: reliable, transient local, keep last 1
    (a late listener still gets the transforms)."""
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )

    never = QosTime(0, 0)
    return Qos(
        QosHistory.KEEP_LAST,
        1,
        QosReliability.RELIABLE,
        QosDurability.TRANSIENT_LOCAL,
        never,
        never,
        QosLiveliness.AUTOMATIC,
        never,
        False,
    )


def _tf_message(motion: Motion, options: ExportOptions, store: Any) -> Any:
    T = store.types
    transforms = []
    for parent, child, pose in static_transforms(motion, options):
        (p,), (q,) = ros_poses(pose[None])
        transforms.append(
            T["geometry_msgs/msg/TransformStamped"](
                header=T["std_msgs/msg/Header"](
                    stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=parent
                ),
                child_frame_id=child,
                transform=T["geometry_msgs/msg/Transform"](
                    translation=T["geometry_msgs/msg/Vector3"](
                        x=float(p[0]), y=float(p[1]), z=float(p[2])
                    ),
                    rotation=T["geometry_msgs/msg/Quaternion"](
                        x=float(q[1]), y=float(q[2]), z=float(q[3]), w=float(q[0])
                    ),
                ),
            )
        )
    return T[TF_TYPE](transforms=transforms)


def _messages(motion: Motion, frame: str, store: Any) -> tuple[Any, Any]:
    """(Path, PoseArray) message objects of the typestore, in the part's frame `frame`."""
    T = store.types
    xyz, q = ros_poses(motion.poses_part)
    poses = [
        T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=float(p[0]), y=float(p[1]), z=float(p[2])),
            orientation=T["geometry_msgs/msg/Quaternion"](
                x=float(r[1]), y=float(r[2]), z=float(r[3]), w=float(r[0])
            ),
        )
        for p, r in zip(xyz, q, strict=True)
    ]

    def header(t: float) -> Any:
        sec, nanosec = split_stamp(t)
        return T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=frame
        )

    path = T[PATH_TYPE](
        header=header(0.0),
        poses=[
            T["geometry_msgs/msg/PoseStamped"](header=header(float(ti)), pose=pose)
            for ti, pose in zip(arrival_times(motion), poses, strict=True)
        ],
    )
    return path, T[POSES_TYPE](header=header(0.0), poses=poses)


def _is_bag(path: Path) -> bool:
    return path.is_dir() and not path.is_symlink() and (path / "metadata.yaml").is_file()


def write_rosbag(motion: Motion, options: ExportOptions, path: str | os.PathLike) -> None:
    """Write the rosbag2 directory `path` (replacing an existing rosbag2 directory there)."""
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.errors import WriterError

    target = Path(path)
    if target.name in ("", ".", ".."):
        raise ValueError(f"rosbag2 output {path}: needs a directory name")
    if (target.exists() or target.is_symlink()) and not _is_bag(target):
        raise ValueError(
            f"rosbag2 output {target} exists and is not a rosbag2 directory; not replacing it"
        )
    target.parent.mkdir(parents=True, exist_ok=True)
    store = _typestore()
    path_msg, poses_msg = _messages(motion, options.ros_frame_id, store)
    staging = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp"))
    try:
        bag = staging / target.name  # the .db3 inside is named after the bag directory
        try:
            with Writer(bag, version=BAG_VERSION) as writer:
                extra = {
                    "scanning": ",".join("1" if s else "0" for s in motion.scanning),
                    "swath": ",".join(str(int(k)) for k in motion.swath),
                    "speed_mm_s": ",".join(repr(float(v)) for v in motion.speed_mm_s),
                    "standoff_mm": repr(float(motion.standoff_mm)),
                }
                for key, value in extra.items():
                    writer.set_custom_data(f"scanplan.{key}", value)
                for topic, msgtype, msg in (
                    (PATH_TOPIC, PATH_TYPE, path_msg),
                    (POSES_TOPIC, POSES_TYPE, poses_msg),
                    (TF_STATIC_TOPIC, TF_TYPE, _tf_message(motion, options, store)),
                ):
                    qos = [_tf_qos()] if topic == TF_STATIC_TOPIC else []
                    conn = writer.add_connection(
                        topic, msgtype, typestore=store, offered_qos_profiles=qos
                    )
                    writer.write(conn, 0, store.serialize_cdr(msg, msgtype))
            replace_directory(bag, target)
        except WriterError as exc:
            raise ValueError(f"cannot write rosbag2 {target}: {exc}") from None
        except sqlite3.Error as exc:  # a full disk is "database or disk is full" here
            raise OSError(f"cannot write rosbag2 {target}: {exc}") from None
        except OSError as exc:
            raise cannot_write(f"rosbag2 {target}", exc) from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)


@dataclass(frozen=True)
class RosbagContents:
    """What `read_rosbag` recovers.

    poses: (n, 4, 4) `T_base_sensor`, mm (from the PoseArray in the part's frame, placed by
    the static transform base -> part, the TCP's standoff undone; the Path must agree);
    stamps_s: (n,) the Path's pose stamps; scanning (n,) bool, swath (n,) int,
    speed_mm_s (n,) from the metadata's custom_data; frame_id: the messages' (the part's)
    frame; transforms: [(parent, child, (4, 4) mm)] from /tf_static (none in a bag written
    before the part frame); topics: {topic: msgtype}; message_counts: {topic: messages}.
    """

    poses: np.ndarray
    stamps_s: np.ndarray
    scanning: np.ndarray
    swath: np.ndarray
    speed_mm_s: np.ndarray
    frame_id: str
    transforms: list[tuple[str, str, np.ndarray]]
    topics: dict[str, str]
    message_counts: dict[str, int]


def _pose_matrices(poses: list[Any]) -> np.ndarray:
    xyz = np.array([[p.position.x, p.position.y, p.position.z] for p in poses]) * 1000.0
    xyzw = np.array([[p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w]
                     for p in poses])  # fmt: skip
    return poses_from_parts(xyz.reshape(-1, 3), Rotation.from_quat(xyzw.reshape(-1, 4)))


def read_rosbag(path: str | os.PathLike) -> RosbagContents:
    """Read a rosbag2 directory written by `write_rosbag` back (for checks and tests)."""
    from rosbags.rosbag2 import Reader
    from rosbags.rosbag2.errors import ReaderError

    path = Path(path)
    store = _typestore()
    msgs: dict[str, Any] = {}
    try:
        with Reader(path) as reader:
            topics = {c.topic: c.msgtype for c in reader.connections}
            counts = {c.topic: c.msgcount for c in reader.connections}
            for conn, _, raw in reader.messages():
                msgs[conn.topic] = store.deserialize_cdr(raw, conn.msgtype)
        meta = yaml.safe_load((path / "metadata.yaml").read_text())
        custom = meta["rosbag2_bagfile_information"]["custom_data"]
        extra = {k: custom[f"scanplan.{k}"].split(",") for k in _KEYS}
        standoff_mm = float(custom.get("scanplan.standoff_mm", 0.0))
        path_msg, poses_msg = msgs[PATH_TOPIC], msgs[POSES_TOPIC]
    except (ReaderError, KeyError, TypeError, ValueError, yaml.YAMLError) as exc:
        raise ValueError(f"not a scanplan rosbag2 directory {path}: {exc}") from None
    poses = _pose_matrices(poses_msg.poses)
    path_poses = _pose_matrices([p.pose for p in path_msg.poses])
    if path_poses.shape != poses.shape or not np.allclose(path_poses, poses, atol=1e-9):
        raise ValueError(f"rosbag2 {path}: path and pose array hold different poses")
    frames = {poses_msg.header.frame_id, path_msg.header.frame_id}
    frames |= {p.header.frame_id for p in path_msg.poses}
    if len(frames) != 1:
        raise ValueError(f"rosbag2 {path}: messages in different frames {sorted(frames)}")
    frame = frames.pop()
    transforms = [
        (
            t.header.frame_id,
            t.child_frame_id,
            matrix_of(
                {k: getattr(t.transform.translation, k) for k in "xyz"},
                {k: getattr(t.transform.rotation, k) for k in "xyzw"},
            ),
        )
        for t in getattr(msgs.get(TF_STATIC_TOPIC), "transforms", [])
    ]
    stamps = np.array([p.header.stamp.sec + p.header.stamp.nanosec * 1e-9 for p in path_msg.poses])
    return RosbagContents(
        poses=sensor_poses(base_poses(poses, frame, transforms), standoff_mm),
        stamps_s=stamps,
        scanning=np.array([v == "1" for v in extra["scanning"]], dtype=bool),
        swath=np.array([int(v) for v in extra["swath"]], dtype=int),
        speed_mm_s=np.array([float(v) for v in extra["speed_mm_s"]]),
        frame_id=frame,
        transforms=transforms,
        topics=topics,
        message_counts=counts,
    )
