"""Frame maths, options and the motion plan shared by every robot-program dialect.

Every dialect writes the same `Motion`: the sensor poses in the robot base frame
(`T_base_sensor = part_pose @ T_part_sensor`, mm), a commanded speed per move and where the
path may be blended. Keeping that decision here means the five files can never disagree.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from scanplan.quantities import ScanSpec
from scanplan.trajectory import Trajectory, pass_bounds

_IDENT = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,23}")  # KRL allows 24 characters, RAPID 32


def _check_rigid(name: str, T: np.ndarray) -> np.ndarray:
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise ValueError(f"{name} must be a finite 4x4 matrix, got shape {T.shape}")
    R = T[:3, :3]
    if (
        not np.allclose(T[3], [0, 0, 0, 1], atol=1e-9)
        or not np.allclose(R.T @ R, np.eye(3), atol=1e-6)
        or np.linalg.det(R) < 0
    ):
        raise ValueError(f"{name} must be a rigid transform (rotation + translation)")
    return T


@dataclass(frozen=True, eq=False)  # array fields: == would be ambiguous
class ExportOptions:
    """How a trajectory becomes a robot program.

    part_pose: (4, 4) `T_base_part`, mm — where the part sits in the robot base frame.
    tcp:       (4, 4) `T_flange_sensor`, mm — the sensor mounted on the tool flange.
    scan:      the ScanSpec: scan speed = its profile rate × Δs_opt (the speed at which
               profiles land Δs_opt apart) unless `scan_speed_mm_s` is given; its travel speed
               between passes.
    joints_rad: (n, 6) the arm's joint angles at each target (the reach check's, as its
               controller counts them), None: no arm checked. With them, the program reaches
               the first target of every pass by a joint move into that configuration (the
               arm may reconfigure only between passes), then moves linearly as before.
    """

    part_pose: np.ndarray = field(default_factory=lambda: np.eye(4))
    tcp: np.ndarray = field(default_factory=lambda: np.eye(4))
    scan: ScanSpec = field(default_factory=ScanSpec)
    scan_speed_mm_s: float | None = None
    accel_mm_s2: float = 1000.0
    blend_mm: float = 1.0
    program_name: str = "scanplan_path"
    ros_frame_id: str = "base_link"
    joints_rad: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "part_pose", _check_rigid("part pose", self.part_pose))
        object.__setattr__(self, "tcp", _check_rigid("tcp", self.tcp))
        if not np.isfinite(self.accel_mm_s2) or self.accel_mm_s2 <= 0:
            raise ValueError(f"export option accel_mm_s2 must be > 0, got {self.accel_mm_s2}")
        if self.scan_speed_mm_s is not None and not (
            np.isfinite(self.scan_speed_mm_s) and self.scan_speed_mm_s > 0
        ):
            raise ValueError(
                f"export option scan_speed_mm_s must be > 0, got {self.scan_speed_mm_s}"
            )
        if not np.isfinite(self.blend_mm) or self.blend_mm < 0:
            raise ValueError(f"export option blend_mm must be >= 0, got {self.blend_mm}")
        if not _IDENT.fullmatch(self.program_name):
            raise ValueError(
                f"program name {self.program_name!r} must be a letter followed by at most 23 "
                "letters, digits or underscores (a valid URScript/RAPID/KRL identifier)"
            )

    @property
    def scan_speed(self) -> float:
        """mm/s commanded while the sensor records."""
        if self.scan_speed_mm_s is not None:
            return float(self.scan_speed_mm_s)
        return self.scan.scan_speed_mm_s

    @property
    def travel_speed_mm_s(self) -> float:
        return self.scan.travel_speed_mm_s


@dataclass(frozen=True)
class Motion:
    """The program every dialect writes, one entry per target pose.

    poses:      (n, 4, 4) `T_base_sensor`, mm.
    poses_part: (n, 4, 4) `T_part_sensor`, mm: the targets a program writes under a work
                object / base frame `part_pose` (`T_base_part`) calibrated on the cell, so
                moving the part means changing one frame, not every target.
    scanning:   (n,) bool; swath: (n,) int.
    pass_start, pass_end: (n,) bool — first / last pose of each scanning run.
    speed_mm_s: (n,) speed of the move that ends at pose i.
    blend_mm:   (n,) blend radius at pose i; 0 = exact stop (pass ends and transitions).
    """

    poses: np.ndarray
    scanning: np.ndarray
    swath: np.ndarray
    pass_start: np.ndarray
    pass_end: np.ndarray
    speed_mm_s: np.ndarray
    blend_mm: np.ndarray
    poses_part: np.ndarray
    part_pose: np.ndarray


def plan_motion(traj: Trajectory, options: ExportOptions) -> Motion:
    if len(traj) == 0:
        raise ValueError("cannot export an empty trajectory")
    poses = options.part_pose @ traj.poses
    start, end = pass_bounds(traj.scanning, traj.swath)
    # Entering a pass is still a travel move; only moves between two recorded poses scan.
    speed = np.where(traj.scanning & ~start, options.scan_speed, options.travel_speed_mm_s)
    # Blends of neighbouring targets must not overlap (UR stops with an error if they do,
    # RAPID/KRL shrink them silently): cap each radius at half the shorter adjacent segment.
    seg = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    room = 0.5 * np.minimum(np.r_[np.inf, seg], np.r_[seg, np.inf])
    blend = np.minimum(options.blend_mm, room)
    blend = np.where(traj.scanning & ~start & ~end, blend, 0.0)
    return Motion(
        poses, traj.scanning, traj.swath, start, end, speed, blend, traj.poses, options.part_pose
    )


def flange_poses(traj: Trajectory, options: ExportOptions) -> np.ndarray:
    """(n, 4, 4) `T_base_flange` in mm, the input of `scanplan.robot.check_reach`."""
    return options.part_pose @ traj.poses @ np.linalg.inv(options.tcp)


# --- rotations ---------------------------------------------------------------------------


def euler_zyx_deg(R: np.ndarray) -> np.ndarray:
    """(…, 3) KUKA A, B, C: intrinsic Z-Y'-X'' Euler angles in degrees."""
    with warnings.catch_warnings():
        # At B = ±90° scipy warns and sets C = 0; the angles still reproduce the rotation.
        warnings.simplefilter("ignore", UserWarning)
        return Rotation.from_matrix(R).as_euler("ZYX", degrees=True)


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
    poses = np.tile(np.eye(4), (len(xyz_mm), 1, 1))
    poses[:, :3, :3] = rot.as_matrix().reshape(-1, 3, 3)
    poses[:, :3, 3] = xyz_mm
    return poses


def parse_pose_arg(s: str) -> np.ndarray:
    """ "x,y,z,A,B,C" -> 4x4: x, y, z in mm, then A, B, C in degrees as KUKA writes them
    (intrinsic ZYX Euler: A about Z, B about the new Y', C about the new X'')."""
    cells = [c.strip() for c in str(s).split(",")]
    usage = "expected 6 comma-separated numbers x,y,z (mm),A,B,C (deg, ZYX Euler as KUKA)"
    if len(cells) != 6:
        raise ValueError(f"pose {s!r}: {usage}, got {len(cells)} value(s)")
    try:
        values = [float(c) for c in cells]
    except ValueError:
        raise ValueError(f"pose {s!r}: {usage}; not a number in it") from None
    if not np.isfinite(values).all():
        raise ValueError(f"pose {s!r}: values must be finite")
    return pose_from_xyzabc(values)


# --- reading programs back -----------------------------------------------------------------


@dataclass(frozen=True)
class Parsed:
    """What a dialect's parser recovers from a program: enough to check it against `Motion`.

    poses: (n, 4, 4) `T_base_sensor`, mm; scanning: (n,) bool; speed_mm_s: (n,);
    blended: (n,) bool (None where the format holds no blending, e.g. ROS).
    """

    poses: np.ndarray
    scanning: np.ndarray
    speed_mm_s: np.ndarray
    blended: np.ndarray | None


class PassTracker:
    """Recovers scanning flags from the `pass k start` / `pass k end` comments around moves."""

    def __init__(self) -> None:
        self.inside = False
        self.flags: list[bool] = []
        self._pending_start = False

    def line(self, text: str) -> None:
        if re.search(r"\bpass \d+ start\b", text):
            self._pending_start = True
        elif re.search(r"\bpass \d+ end\b", text):
            self.inside = False

    def move(self) -> None:
        if self._pending_start:
            self.inside, self._pending_start = True, False
        self.flags.append(self.inside)


def floats(text: str) -> list[float]:
    return [float(v) for v in text.replace(" ", "").split(",") if v]


# Joint moves into a pass's configuration: a moderate share of any arm's axis speed.
JOINT_SPEED_DEG_S = 60.0
JOINT_ACCEL_DEG_S2 = 120.0


def joint_move_targets(motion: Motion, options: ExportOptions) -> dict[int, np.ndarray]:
    """{target index: joint angles (6,) rad} where the program moves by joint: the first
    target of every pass, when the options carry the arm's joints."""
    if options.joints_rad is None:
        return {}
    joints = np.asarray(options.joints_rad, dtype=np.float64)
    if joints.shape != (len(motion.poses), 6):
        raise ValueError(f"joints must be ({len(motion.poses)}, 6), got {joints.shape}")
    return {
        int(i): joints[i] for i in np.flatnonzero(motion.pass_start) if np.isfinite(joints[i]).all()
    }
