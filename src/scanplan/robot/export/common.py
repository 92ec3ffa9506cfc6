"""Options, the motion plan and the read-back helpers shared by every robot-program dialect
(the rotation conventions they share: `rotations`).

Every dialect writes the same `Motion`: the poses of the program's TCP in the robot base
frame, a commanded speed per move and where the path may be blended. The TCP is where the
laser line meets the part at the working distance (`ScanSpec.T_sensor_line`, W_d along the
beam), not the sensor's origin W_d behind it: the controller's constant TCP speed is then
the line's speed over the surface (profiles Δs apart where the part is at W_d), and linear
moves, thinning and blends act on the surface path. Keeping that decision here means the
five files can never disagree; their parsers undo the standoff they record
(`TCP_STANDOFF`), so a program reads back as `T_base_sensor`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import Trajectory, pass_bounds, pass_entries
from scanplan.robot.axes import ExternalAxes, axis_steps, kept, part_poses
from scanplan.robot.export.thinning import thin

_IDENT = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,23}")  # KRL allows 24 characters, RAPID 32
_FRAME = re.compile(r"[A-Za-z_][A-Za-z0-9_/]*")  # a tf2 frame id

# Thinning defaults, as shares of the in-spec tolerances (ScanSpec): the flown path may stray
# 1/25 of the depth tolerance (0.5 mm of Z_r/20 = 12.5 mm for the default sensor) and 1/30 of
# the angle tolerance (0.5° of 15°), so a point in spec by the plan stays in spec flown unless
# it was within a few percent of a limit, and coverage moves by well under 0.01.
DEFAULT_CHORD_SHARE = 1.0 / 25.0
DEFAULT_ANGLE_SHARE = 1.0 / 30.0

# A move between passes may cut its corners by this share of the clearance its poses were
# planned with (ScanSpec.clearance_mm: 5 mm of the default 20 mm), on top of the chord
# tolerance of its thinning: the rest covers the sensor body swinging with the blended
# orientation, so a blended move stays as clear of the cell as its planned poses, near enough.
MOVE_CUT_SHARE = 1.0 / 4.0
# The largest blend radius of a move: at 1 m/s² a 50 mm blend is taken at √(a·r) ≈ 220 mm/s,
# about the travel speed, so the move flies its blended run as one speed profile.
MOVE_BLEND_MM = 50.0


class Kinematics(Protocol):
    """What a dialect needs of the arm (`scanplan.robot.Robot` has it): (…, 3) signed terms
    per joint vector — sin of the wrist angle, the elbow's side of the line through the
    upper arm, the wrist centre's x in the frame turning with axis 1 (mm)."""

    def singularity_terms(self, q: np.ndarray) -> np.ndarray: ...


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
    tcp:       (4, 4) `T_flange_sensor`, mm — the sensor mounted on the tool flange; the
               program's tool is `tool` = `T_flange_sensor @ scan.T_sensor_line`.
    scan:      the ScanSpec: scan speed = its profile rate × Δs_opt (the speed at which
               profiles land Δs_opt apart) unless `scan_speed_mm_s` is given; its travel speed
               between passes.
    joints_rad: (n, 6) the arm's joint angles at each planned pose (the reach check's, as
               its controller counts them), None: no arm checked. With them, the program
               reaches the first target of every pass by a joint move into that configuration
               (the arm may reconfigure only between passes), then moves linearly as before.
    arm:       the arm those joints are of (anything with the robot's `singularity_terms`),
               for the configuration a dialect writes with a Cartesian target (KUKA Status,
               ABB cfx); None: no arm.
    chord_tol_mm, angle_tol_deg: how far the flown path may stray from the planned poses
               once each run is thinned to few targets (`scanplan.robot.export.thinning`); None:
               the defaults, `DEFAULT_CHORD_SHARE` of the in-spec depth tolerance and
               `DEFAULT_ANGLE_SHARE` of the in-spec angle tolerance.
    blend_mm:  the largest blend radius in a pass (further capped per target, see
               `blend_radii`).
    move_blend_mm: the largest blend radius of a move between passes (`MOVE_BLEND_MM`).
    ros_frame_id: the part's frame in the ROS 2 exports: their targets are `T_part_tcp` in it,
               and a static transform from `ros_base_frame_id` (the part pose) places it.
    ros_base_frame_id, ros_flange_frame_id, ros_tcp_frame_id: the arm's base and flange
               frames (ROS-Industrial's `base_link`, `tool0`) and the TCP frame the static
               transform of the tool (`tool`) names.
    scan_output: the output that switches the sensor's acquisition on over each pass: a
               digital output number (URScript standard output 0-7, KRL $OUT 1-4096) or a
               RAPID signal name; None: each dialect's default (`DEFAULT_SCAN_OUTPUT`).
    axes:      the cell's external axes (`robot.axes`), their values the trajectory's
               (`Trajectory.external`); `part_pose` is then the part at every axis at 0.
    """

    part_pose: np.ndarray = field(default_factory=lambda: np.eye(4))
    tcp: np.ndarray = field(default_factory=lambda: np.eye(4))
    scan: ScanSpec = field(default_factory=ScanSpec)
    scan_speed_mm_s: float | None = None
    accel_mm_s2: float = 1000.0
    blend_mm: float = 5.0
    move_blend_mm: float = MOVE_BLEND_MM
    program_name: str = "scanplan_path"
    ros_frame_id: str = "scan_part"
    ros_base_frame_id: str = "base_link"
    ros_flange_frame_id: str = "tool0"
    ros_tcp_frame_id: str = "scan_tcp"
    joints_rad: np.ndarray | None = None
    arm: Kinematics | None = None
    chord_tol_mm: float | None = None
    angle_tol_deg: float | None = None
    scan_output: str | None = None
    axes: ExternalAxes | None = None

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
        tolerances = (("chord_tol_mm", self.chord_tol_mm), ("angle_tol_deg", self.angle_tol_deg))
        for what, tol in tolerances:
            if tol is not None and not (np.isfinite(tol) and tol > 0):
                raise ValueError(f"export option {what} must be a finite number > 0, got {tol}")
        for what, radius in (("blend_mm", self.blend_mm), ("move_blend_mm", self.move_blend_mm)):
            if not np.isfinite(radius) or radius < 0:
                raise ValueError(f"export option {what} must be >= 0, got {radius}")
        frames = (
            self.ros_frame_id,
            self.ros_base_frame_id,
            self.ros_flange_frame_id,
            self.ros_tcp_frame_id,
        )
        for frame in frames:
            if not _FRAME.fullmatch(frame):
                raise ValueError(
                    f"ROS frame {frame!r} must be a letter or underscore followed by letters, "
                    "digits, underscores or slashes"
                )
        if len(set(frames)) != len(frames):
            raise ValueError(f"ROS frames must differ: part, base, flange, TCP = {frames}")
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

    @property
    def standoff_mm(self) -> float:
        """mm from the sensor's origin along its beam to the program's TCP (W_d)."""
        return self.scan.working_distance_mm

    @property
    def tool(self) -> np.ndarray:
        """(4, 4) `T_flange_tcp`, mm: the tool frame the program sets."""
        return self.tcp @ self.scan.T_sensor_line

    @property
    def chord_tol(self) -> float:
        """mm the thinned path may stray from a planned pose's position."""
        if self.chord_tol_mm is not None:
            return float(self.chord_tol_mm)
        return DEFAULT_CHORD_SHARE * self.scan.tolerance_mm

    @property
    def move_cut_mm(self) -> float:
        """mm a move's blend may cut a corner of its path (`MOVE_CUT_SHARE` of the clearance)."""
        return MOVE_CUT_SHARE * self.scan.clearance_mm

    @property
    def angle_tol_rad(self) -> float:
        """rad the thinned path may turn away from a planned pose's orientation."""
        if self.angle_tol_deg is not None:
            return float(np.radians(self.angle_tol_deg))
        return DEFAULT_ANGLE_SHARE * self.scan.tol_angle_rad


@dataclass(frozen=True)
class Motion:
    """The program every dialect writes, one entry per target pose: the planned poses thinned
    run by run (`scanplan.robot.export.thinning`) to the fewest within the options' chord and angle
    tolerances.

    poses:      (n, 4, 4) `T_base_tcp`, mm: the TCP (the laser line at W_d) in the base frame.
    poses_part: (n, 4, 4) `T_part_tcp`, mm: the targets a program writes under a work
                object / base frame `part_pose` (`T_base_part`) calibrated on the cell, so
                moving the part means changing one frame, not every target.
    scanning:   (n,) bool; swath: (n,) int.
    pass_start, pass_end: (n,) bool — first / last pose of each scanning run.
    speed_mm_s: (n,) speed of the move that ends at pose i.
    blend_mm:   (n,) blend radius at pose i; 0 = exact stop (the program's first and last
                target, each pass's start and end, the start of a joint move into a pass).
    source:     (n,) int, the index of each target among the planned poses.
    n_planned:  how many planned poses the targets were thinned from.
    standoff_mm: the TCP's offset from the sensor's origin along its beam (`TCP_STANDOFF`).
    external:   (n, k) the external axes' values at each target (None: the arm alone);
    axis_step:  (n,) bool, targets reached by a joint move on which the turntable turns (the
                arm stands still before it; the first target of each view).
    axes:       the external axes (None: none).
    entry:      (n,) bool, the targets each pass is entered at by a joint move
                (`trajectory.pass_entries`: the top of its lead-in, or its first pose).
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
    source: np.ndarray
    n_planned: int
    standoff_mm: float
    external: np.ndarray | None = None
    axis_step: np.ndarray | None = None
    axes: ExternalAxes | None = None
    entry: np.ndarray | None = None

    def part_poses(self) -> np.ndarray:
        """(n, 4, 4) `T_base_part` at each target (the part moved by the axes)."""
        return np.broadcast_to(
            part_poses(self.part_pose, self.external, self.axes), (len(self.poses), 4, 4)
        )


def plan_motion(traj: Trajectory, options: ExportOptions) -> Motion:
    if len(traj) == 0:
        raise ValueError("cannot export an empty trajectory")
    start, end = pass_bounds(traj.scanning, traj.swath)
    # Pass starts and ends stay targets (the acquisition switches there); every run between
    # them, scanning or not, keeps the fewest poses within the tolerances.
    # Thinned on the TCP's path: the one the controller interpolates linearly.
    tcp_part = traj.poses @ options.scan.T_sensor_line
    if (traj.external is None) != (options.axes is None):
        raise ValueError(
            "the plan's external axis values and the program's axes do not match (a plan "
            "made with a positioner or track exports with them)"
        )
    step = axis_steps(traj, options.axes)
    entry = pass_entries(traj)
    keep = thin(
        tcp_part,
        start | end | entry | step | np.r_[step[1:], False],
        options.chord_tol,
        options.angle_tol_rad,
    )
    poses_part = tcp_part[keep]
    poses = kept(part_poses(options.part_pose, traj.external, options.axes), keep) @ poses_part
    scanning, start, end = traj.scanning[keep], start[keep], end[keep]
    step, entry = step[keep], entry[keep]
    # Entering a pass is still a travel move; only moves between two recorded poses scan.
    speed = np.where(scanning & ~start, options.scan_speed, options.travel_speed_mm_s)
    # Exact stops where the acquisition switches, at the ends of the program, and where a
    # joint move into a pass starts (its swept path is checked from a standing arm).
    n = len(keep)
    stop = (
        start | end | step | np.r_[step[1:], False] | (np.arange(n) == 0) | (np.arange(n) == n - 1)
    )
    if options.joints_rad is not None:
        joints = np.asarray(options.joints_rad, dtype=np.float64)[keep]
        into = entry[1:] & np.isfinite(joints[1:]).all(axis=1)
        stop[:-1] |= into
        stop[1:] |= into  # the joint move ends standing, then flies the lead-in linearly
    return Motion(
        poses,
        scanning,
        traj.swath[keep],
        start,
        end,
        speed,
        blend_radii(poses, scanning & ~stop, ~scanning & ~stop, options),
        poses_part,
        options.part_pose,
        keep,
        len(traj),
        options.standoff_mm,
        None if traj.external is None else traj.external[keep],
        step,
        options.axes,
        entry,
    )


def blend_radii(
    poses: np.ndarray, in_pass: np.ndarray, in_move: np.ndarray, options: ExportOptions
) -> np.ndarray:
    """(n,) blend radius at each target, mm; 0 (exact stop) where neither `in_pass` nor
    `in_move` (n,) bool is set.

    A blend of radius r around a corner that turns the path by θ cuts it by at most
    r·sin(θ/2): capped so that stays within the chord tolerance in a pass, and within
    `ExportOptions.move_cut_mm` (a share of the clearance) in a move between passes. Blends
    of neighbouring targets must not overlap either (UR stops with an error if they do,
    RAPID/KRL shrink them silently): capped at half the shorter adjacent move.
    """
    step = np.diff(poses[:, :3, 3], axis=0)
    seg = np.linalg.norm(step, axis=1)
    room = 0.5 * np.minimum(np.r_[np.inf, seg], np.r_[seg, np.inf])
    unit = step / np.maximum(seg, 1e-12)[:, None]
    cos_turn = np.clip(np.einsum("ij,ij->i", unit[:-1], unit[1:]), -1.0, 1.0)
    half_sin = np.maximum(np.r_[0.0, np.sqrt((1.0 - cos_turn) / 2.0), 0.0], 1e-12)  # sin(θ/2)
    straight = half_sin <= 1e-12
    scan_r = np.where(straight, options.blend_mm, options.chord_tol / half_sin)
    move_r = np.where(straight, options.move_blend_mm, options.move_cut_mm / half_sin)
    scan_r = np.minimum(np.minimum(scan_r, options.blend_mm), room)
    move_r = np.minimum(np.minimum(move_r, options.move_blend_mm), room)
    return np.where(in_pass, scan_r, np.where(in_move, move_r, 0.0))


def flange_poses(traj: Trajectory, options: ExportOptions) -> np.ndarray:
    """(n, 4, 4) `T_base_flange` in mm, the input of `scanplan.robot.check_reach`: the same
    whichever TCP the program flies (`T_base_tcp @ inv(tool)` is this)."""
    T = part_poses(options.part_pose, traj.external, options.axes)
    return T @ traj.poses @ np.linalg.inv(options.tcp)


# --- reading programs back -----------------------------------------------------------------

# What every program's header records of its TCP, in the dialect's comment syntax; a program
# without it (written before the TCP moved to the line) flies the sensor's origin.
TCP_STANDOFF = re.compile(r"TCP standoff ([-+0-9.eE]+) mm along the sensor's beam")


def standoff_note(motion: Motion) -> str:
    """The header text `TCP_STANDOFF` reads back, and why."""
    return (
        f"TCP standoff {motion.standoff_mm:.6g} mm along the sensor's beam (z): the tool is "
        "where the laser line meets the part at the working distance, so the commanded "
        "speed is the line's speed over the surface"
    )


def read_standoff(text: str) -> float:
    """mm, the standoff a program's header records (`standoff_note`); 0 when none."""
    m = TCP_STANDOFF.search(text)
    return float(m.group(1)) if m else 0.0


def sensor_poses(poses_tcp: np.ndarray, standoff_mm: float | np.ndarray) -> np.ndarray:
    """(n, 4, 4) `T_x_sensor` of the TCP poses `T_x_tcp` (mm) of a program with that standoff
    (mm, one or (n,)): each moved back along its own z."""
    poses = np.array(poses_tcp, dtype=np.float64)
    poses[..., :3, 3] -= np.asarray(standoff_mm, dtype=np.float64)[..., None] * poses[..., :3, 2]
    return poses


@dataclass(frozen=True)
class Parsed:
    """What a dialect's parser recovers from a program: enough to check it against `Motion`.

    poses: (n, 4, 4) `T_base_sensor`, mm (with external axes: at their values); scanning:
    (n,) bool; speed_mm_s: (n,); blended: (n,) bool (None where the format holds no
    blending, e.g. ROS); external: (n, k) the external axes' values (None: none).
    """

    poses: np.ndarray
    scanning: np.ndarray
    speed_mm_s: np.ndarray
    blended: np.ndarray | None
    external: np.ndarray | None = None


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


def scan_output(options: ExportOptions, default: str, kind: str) -> str:
    """The acquisition output a dialect writes: `options.scan_output` or `default`, checked
    as `kind` "number LO-HI" (a digital output number) or "name" (a signal identifier)."""
    value = default if options.scan_output is None else str(options.scan_output).strip()
    if kind == "name":
        if not _IDENT.fullmatch(value):
            raise ValueError(
                f"scan output {value!r} must be a signal name (a letter, then letters, digits "
                "or underscores)"
            )
        return value
    lo, hi = (int(v) for v in kind.split()[1].split("-"))
    if not (value.isdigit() and lo <= int(value) <= hi):
        raise ValueError(f"scan output {value!r} must be a digital output number {lo}-{hi}")
    return str(int(value))
