"""ROS 2 YAML: the path as a `geometry_msgs/PoseArray` and a `nav_msgs/Path` (metres) in the
part's frame, and the static transforms that place it and the TCP.

One YAML mapping with four keys: `pose_array`, `path` and `tf_static` (a
`tf2_msgs/TFMessage`) are the messages exactly as `ros2 topic pub` / rosidl YAML expects
them, `scanplan` carries what no message holds (the scanning flags, swath indices, speeds and
the TCP's standoff from the sensor, `standoff_mm`). Poses are `T_part_tcp`, the TCP (where
the laser line meets the part at the working distance) in the part's frame
(`ExportOptions.ros_frame_id`), so moving the part changes one transform: `tf_static` holds
base -> part (`T_base_part`) and flange -> TCP (the tool), calibrated once on the cell. Path
stamps are the planned arrival times from the start (distance / commanded speed,
accelerations ignored). The same two messages as a rosbag2
directory: `scanplan.robot.export.rosbag`, built on `ros_poses` and `arrival_times` here.
"""

from __future__ import annotations

import json

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from scanplan.robot.axes import ExternalAxes
from scanplan.robot.export.axes_lines import on_axes
from scanplan.robot.export.common import (
    ExportOptions,
    Motion,
    Parsed,
    sensor_poses,
    standoff_note,
)
from scanplan.robot.export.rotations import poses_from_parts, quat_wxyz

SUFFIX = ".yaml"


def split_stamp(t: float) -> tuple[int, int]:
    """(sec, nanosec) of a `builtin_interfaces/Time` for `t` seconds (nanosec < 1e9)."""
    sec, nanosec = divmod(int(round(t * 1e9)), 1_000_000_000)
    return sec, nanosec


def _stamp(t: float) -> str:
    sec, nanosec = split_stamp(t)
    return f"{{sec: {sec}, nanosec: {nanosec}}}"


def ros_poses(poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(positions (n, 3) in metres, quaternions (n, 4) scalar *first*) of (n, 4, 4) poses in
    mm; ROS messages order the quaternion x, y, z, w."""
    return poses[:, :3, 3] / 1000.0, quat_wxyz(poses[:, :3, :3])


def static_transforms(motion: Motion, options: ExportOptions) -> list[tuple[str, str, np.ndarray]]:
    """[(parent frame, child frame, (4, 4) `T_parent_child` in mm)]: the part in the base
    frame and the TCP on the flange, what a static transform broadcaster publishes."""
    return [
        (options.ros_base_frame_id, options.ros_frame_id, motion.part_pose),
        (options.ros_flange_frame_id, options.ros_tcp_frame_id, options.tool),
    ]


def base_poses(
    poses: np.ndarray, frame: str, transforms: list[tuple[str, str, np.ndarray]]
) -> np.ndarray:
    """(n, 4, 4) `T_base_x` of (n, 4, 4) `T_frame_x`: composed with the transform whose
    child is `frame`; as they are where none is (a file from before the part frame, whose
    poses were in the base frame)."""
    for _, child, T in transforms:
        if child == frame:
            return T @ poses
    return poses


def _transform_yaml(parent: str, child: str, T: np.ndarray) -> str:
    (p,), (q,) = ros_poses(T[None])
    return (
        f"- header:\n    stamp: {{sec: 0, nanosec: 0}}\n    frame_id: {parent}\n"
        f"  child_frame_id: {child}\n  transform:\n"
        f"    translation: {{x: {p[0]:.9f}, y: {p[1]:.9f}, z: {p[2]:.9f}}}\n"
        f"    rotation: {{x: {q[1]:.9f}, y: {q[2]:.9f}, z: {q[3]:.9f}, w: {q[0]:.9f}}}"
    )


def matrix_of(translation: dict[str, float], rotation: dict[str, float]) -> np.ndarray:
    """(4, 4) in mm of a `geometry_msgs/Transform`'s translation (m) and rotation."""
    xyz = np.array([[translation[k] for k in "xyz"]]) * 1000.0
    return poses_from_parts(xyz, Rotation.from_quat([[rotation[k] for k in "xyzw"]]))[0]


def arrival_times(motion: Motion) -> np.ndarray:
    """(n,) planned arrival time at each pose from the start, s (distance / commanded speed,
    accelerations ignored): the path stamps."""
    seg = np.linalg.norm(np.diff(motion.poses[:, :3, 3], axis=0), axis=1)
    return np.r_[0.0, np.cumsum(seg / motion.speed_mm_s[1:])]


# The external axes' joints in `joint_trajectory` (radians, metres, as ROS counts them).
JOINT_NAMES = {"turntable_deg": "turntable_joint", "track_mm": "track_joint"}


def _joint_trajectory(motion: Motion, t: np.ndarray) -> list[str]:
    """`joint_trajectory`, a `trajectory_msgs/JointTrajectory` of the external axes at each
    pose's arrival time, and their record under `scanplan`; none without axes. The part's
    transform in `tf_static` is then the part with every axis at 0."""
    if motion.axes is None or motion.external is None:
        return []
    names = motion.axes.names
    scale = np.where(motion.axes.rotary, np.pi / 180.0, 1e-3)
    out = [
        "joint_trajectory:",
        "  header:",
        "    stamp: {sec: 0, nanosec: 0}",
        "    frame_id: ''",
        f"  joint_names: [{', '.join(JOINT_NAMES[n] for n in names)}]",
        "  points:",
    ]
    for row, ti in zip(motion.external * scale, t, strict=True):
        sec, nanosec = split_stamp(float(ti))
        positions = ", ".join(f"{v:.9f}" for v in row)
        out.append(
            f"  - {{positions: [{positions}], time_from_start: {{sec: {sec}, nanosec: {nanosec}}}}}"
        )
    return out


def write(motion: Motion, options: ExportOptions) -> str:
    frame = options.ros_frame_id
    xyz, q = ros_poses(motion.poses_part)
    t = arrival_times(motion)
    body = [
        f"position: {{x: {p[0]:.9f}, y: {p[1]:.9f}, z: {p[2]:.9f}}}\n"
        f"orientation: {{x: {r[1]:.9f}, y: {r[2]:.9f}, z: {r[3]:.9f}, w: {r[0]:.9f}}}"
        for p, r in zip(xyz, q, strict=True)
    ]
    out = [
        f"# {options.program_name}: laser-profilometer scan path written by scanplan",
        f"# Poses are T_{frame}_tcp, the TCP in the part's frame {frame}, metres and unit",
        f"# quaternions. tf_static places the part ({options.ros_base_frame_id} -> {frame}, "
        "T_base_part) and the TCP",
        f"# ({options.ros_flange_frame_id} -> {options.ros_tcp_frame_id}, the tool): "
        "calibrate them once on the cell; moving the part changes",
        "# one transform. On a UR arm, note that the ROS frame base_link is the controller's",
        "# base frame turned 180 deg about Z.",
        f"# {standoff_note(motion)};",
        "# the sensor's pose is the TCP's moved back by standoff_mm along its z.",
        "scanplan:",
        f"  frame_id: {frame}",
        f"  scanning: [{', '.join('true' if s else 'false' for s in motion.scanning)}]",
        f"  swath: [{', '.join(str(int(k)) for k in motion.swath)}]",
        f"  speed_mm_s: [{', '.join(f'{v:g}' for v in motion.speed_mm_s)}]",
        f"  standoff_mm: {motion.standoff_mm:.9g}",
        *([] if motion.axes is None else [f"  external_axes: {json.dumps(motion.axes.record())}"]),
        "pose_array:",
        "  header:",
        "    stamp: {sec: 0, nanosec: 0}",
        f"    frame_id: {frame}",
        "  poses:",
    ]
    for b in body:
        out.append("  - " + b.replace("\n", "\n    "))
    out += ["path:", "  header:", "    stamp: {sec: 0, nanosec: 0}", f"    frame_id: {frame}"]
    out.append("  poses:")
    for b, ti in zip(body, t, strict=True):
        out.append(f"  - header:\n      stamp: {_stamp(ti)}\n      frame_id: {frame}")
        out.append("    pose:\n      " + b.replace("\n", "\n      "))
    out += _joint_trajectory(motion, t)
    out.append("tf_static:\n  transforms:")
    for parent, child, T in static_transforms(motion, options):
        out.append("  " + _transform_yaml(parent, child, T).replace("\n", "\n  "))
    return "\n".join(out) + "\n"


def parse(text: str) -> Parsed:
    try:
        # libyaml when present: the pure-Python loader takes a minute on a long path.
        doc = yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
        poses_in = [p["pose"] for p in doc["path"]["poses"]]
        array_in = doc["pose_array"]["poses"]
        extra = doc["scanplan"]
        frame = doc["pose_array"]["header"]["frame_id"]
        transforms = [
            (
                t["header"]["frame_id"],
                t["child_frame_id"],
                matrix_of(t["transform"]["translation"], t["transform"]["rotation"]),
            )
            for t in (doc.get("tf_static") or {}).get("transforms", [])
        ]
    except (yaml.YAMLError, KeyError, TypeError) as exc:
        raise ValueError(f"not a scanplan ROS YAML file: {exc}") from None
    if len(poses_in) != len(array_in):
        raise ValueError("ROS YAML: path and pose_array differ in length")
    xyz = np.array([[p["position"][k] for k in "xyz"] for p in array_in]) * 1000.0
    xyzw = np.array([[p["orientation"][k] for k in "xyzw"] for p in array_in])
    poses = poses_from_parts(xyz, Rotation.from_quat(xyzw))
    path_xyz = np.array([[p["position"][k] for k in "xyz"] for p in poses_in]) * 1000.0
    if not np.allclose(path_xyz, xyz, atol=1e-6):
        raise ValueError("ROS YAML: path and pose_array hold different poses")
    # Read back in the base frame, as every dialect's parser returns them.
    axes, values = _external(doc, extra)
    if axes is None:
        poses = base_poses(poses, frame, transforms)
    else:
        base = base_poses(np.eye(4)[None], frame, transforms)[0]
        poses = on_axes(base, poses, values, axes)
    poses = sensor_poses(poses, float(extra.get("standoff_mm", 0.0)))
    return Parsed(
        poses, np.array(extra["scanning"], dtype=bool), np.array(extra["speed_mm_s"]), None, values
    )


def _external(doc: dict, extra: dict) -> tuple[ExternalAxes | None, np.ndarray | None]:
    """The external axes and their values (degrees, mm) a ROS YAML file holds, if any."""
    if "external_axes" not in extra:
        return None, None
    axes = ExternalAxes.of_record(extra["external_axes"], "ROS YAML scanplan.external_axes")
    try:
        points = doc["joint_trajectory"]["points"]
        values = np.array([p["positions"] for p in points], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        raise ValueError("ROS YAML: external axes without a joint_trajectory of them") from None
    if values.ndim != 2 or values.shape[1] != len(axes.names):
        raise ValueError("ROS YAML: joint_trajectory points do not match the external axes")
    return axes, values / np.where(axes.rotary, np.pi / 180.0, 1e-3)
