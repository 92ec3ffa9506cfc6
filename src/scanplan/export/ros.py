"""ROS 2 YAML: the path as a `geometry_msgs/PoseArray` and a `nav_msgs/Path` (metres).

One YAML mapping with three keys: `pose_array` and `path` are the messages exactly as
`ros2 topic pub` / rosidl YAML expects them, `scanplan` carries what no message holds (the
scanning flags, swath indices, speeds and the TCP's standoff from the sensor, `standoff_mm`).
Poses are the TCP's, where the laser line meets the part at the working distance. Path
stamps are the planned arrival times from the start (distance / commanded speed,
accelerations ignored). The same two messages as a rosbag2
directory: `scanplan.export.rosbag`, built on `ros_poses` and `arrival_times` here.
"""

from __future__ import annotations

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from scanplan.export.common import (
    ExportOptions,
    Motion,
    Parsed,
    poses_from_parts,
    quat_wxyz,
    sensor_poses,
    standoff_note,
)

SUFFIX = ".yaml"


def split_stamp(t: float) -> tuple[int, int]:
    """(sec, nanosec) of a `builtin_interfaces/Time` for `t` seconds (nanosec < 1e9)."""
    sec, nanosec = divmod(int(round(t * 1e9)), 1_000_000_000)
    return sec, nanosec


def _stamp(t: float) -> str:
    sec, nanosec = split_stamp(t)
    return f"{{sec: {sec}, nanosec: {nanosec}}}"


def ros_poses(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """(positions (n, 3) in metres, quaternions (n, 4) scalar *first*) of `T_base_tcp`;
    ROS messages order the quaternion x, y, z, w."""
    return motion.poses[:, :3, 3] / 1000.0, quat_wxyz(motion.poses[:, :3, :3])


def arrival_times(motion: Motion) -> np.ndarray:
    """(n,) planned arrival time at each pose from the start, s (distance / commanded speed,
    accelerations ignored): the path stamps."""
    seg = np.linalg.norm(np.diff(motion.poses[:, :3, 3], axis=0), axis=1)
    return np.r_[0.0, np.cumsum(seg / motion.speed_mm_s[1:])]


def write(motion: Motion, options: ExportOptions) -> str:
    frame = options.ros_frame_id
    xyz, q = ros_poses(motion)
    t = arrival_times(motion)
    body = [
        f"position: {{x: {p[0]:.9f}, y: {p[1]:.9f}, z: {p[2]:.9f}}}\n"
        f"orientation: {{x: {r[1]:.9f}, y: {r[2]:.9f}, z: {r[3]:.9f}, w: {r[0]:.9f}}}"
        for p, r in zip(xyz, q, strict=True)
    ]
    out = [
        f"# {options.program_name}: laser-profilometer scan path written by scanplan",
        f"# Poses are T_{frame}_tcp (the TCP in the robot base frame, part_pose @",
        "# T_part_tcp), metres and unit quaternions. On a UR arm, note that the ROS frame",
        "# base_link is the controller's base frame turned 180 deg about Z.",
        f"# {standoff_note(motion)};",
        "# the sensor's pose is the TCP's moved back by standoff_mm along its z.",
        "scanplan:",
        f"  frame_id: {frame}",
        f"  scanning: [{', '.join('true' if s else 'false' for s in motion.scanning)}]",
        f"  swath: [{', '.join(str(int(k)) for k in motion.swath)}]",
        f"  speed_mm_s: [{', '.join(f'{v:g}' for v in motion.speed_mm_s)}]",
        f"  standoff_mm: {motion.standoff_mm:.9g}",
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
    return "\n".join(out) + "\n"


def parse(text: str) -> Parsed:
    try:
        # libyaml when present: the pure-Python loader takes a minute on a long path.
        doc = yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
        poses_in = [p["pose"] for p in doc["path"]["poses"]]
        array_in = doc["pose_array"]["poses"]
        extra = doc["scanplan"]
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
    poses = sensor_poses(poses, float(extra.get("standoff_mm", 0.0)))
    return Parsed(
        poses, np.array(extra["scanning"], dtype=bool), np.array(extra["speed_mm_s"]), None
    )
