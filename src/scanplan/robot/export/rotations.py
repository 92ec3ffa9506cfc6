"""Rotation and pose conventions of the robot-program dialects: KUKA's A, B, C (intrinsic
Z-Y'-X'' Euler angles), scalar-first quaternions, poses from positions and rotations, and the
"x,y,z,A,B,C" pose argument of the CLI.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from scipy.spatial.transform import Rotation

from scanplan.core.limits import POSE_ANGLE_DEG, POSITION_MM, Limit


def pose_from_xyzabc(values: Iterable[float]) -> np.ndarray:
    """4x4 from x, y, z (mm) and KUKA A, B, C (degrees, intrinsic ZYX)."""
    v = np.asarray(list(values), dtype=np.float64)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("ZYX", v[3:6], degrees=True).as_matrix()
    T[:3, 3] = v[:3]
    return T


def quat_wxyz(R: np.ndarray) -> np.ndarray:
    """(…, 4) unit quaternions, scalar first, w >= 0 so files are deterministic."""
    xyzw = Rotation.from_matrix(R).as_quat(canonical=True)
    return np.concatenate([xyzw[..., 3:], xyzw[..., :3]], axis=-1)


def poses_from_parts(xyz_mm: np.ndarray, rot: Rotation) -> np.ndarray:
    """(n, 4, 4) poses from (n, 3) positions (mm) and n rotations."""
    poses = np.tile(np.eye(4), (len(xyz_mm), 1, 1))
    poses[:, :3, :3] = rot.as_matrix().reshape(-1, 3, 3)
    poses[:, :3, 3] = xyz_mm
    return poses


# A --tcp or --part-pose not given is the identity (the frames coincide): said in the output
# wherever it is taken, never silently.
IDENTITY_POSE = "0,0,0,0,0,0"


def parse_pose_arg(s: str, position: Limit = POSITION_MM) -> np.ndarray:
    """ "x,y,z,A,B,C" -> 4x4: x, y, z in mm, then A, B, C in degrees as KUKA writes them
    (intrinsic ZYX Euler: A about Z, B about the new Y', C about the new X''). x, y, z are
    held to `position` (a TCP's to TCP_MM), A, B, C to POSE_ANGLE_DEG: a pose of 1e308 mm
    is a typing mistake, not a place the arm fails to reach."""
    text = str(s)
    shown = repr(text if len(text) <= 80 else f"{text[:77]}...")
    cells = [c.strip() for c in text.split(",")]
    usage = "expected 6 comma-separated numbers x,y,z (mm),A,B,C (deg, ZYX Euler as KUKA)"
    if len(cells) != 6:
        raise ValueError(f"pose {shown}: {usage}, got {len(cells)} value(s)")
    try:
        values = [float(c) for c in cells]
    except ValueError:
        raise ValueError(f"pose {shown}: {usage}; not a number in it") from None
    if not np.isfinite(values).all():
        raise ValueError(f"pose {shown}: values must be finite")
    for name, value in zip("xyzABC", values, strict=True):
        (position if name in "xyz" else POSE_ANGLE_DEG).check(value, f"pose {shown}: {name}")
    return pose_from_xyzabc(values)
