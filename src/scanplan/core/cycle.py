"""Cycle time: how long an arm takes to fly a trajectory, from its motion limits.

One model for `plan`, `evaluate` and `export`: a trapezoidal speed profile (accelerate,
cruise, decelerate; triangular when too short to reach cruise) per pass at the scan speed
and per move segment at the travel speed, and per joint for the joint move into each pass.
Distances are those of the TCP the exported program flies: the laser line at the working
distance (`ScanSpec.T_sensor_line`), not the sensor's origin W_d behind it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import Trajectory, pass_bounds, pass_entries, rotation_deg

CYCLE_TIME_MODEL = (
    "trapezoidal speed profiles (accelerate, cruise, decelerate; triangular when a stretch "
    "is too short to reach cruise speed) at the arm's Cartesian acceleration, on the path of "
    "the TCP the program flies (the laser line at the working distance): each pass one "
    "profile at the scan speed, blended through its targets, slowed where its rotation (at "
    "the angular speed limit) or, with the arm's joints known, a joint (at its speed limit) "
    "needs longer than the scan speed allows; each move between passes or views one "
    "profile at the travel speed over every run of targets it blends through (slowed as a "
    "pass is), a segment between two exact stops timed by its rotation instead where that "
    "takes longer, and by its slowest joint's own trapezoid where the arm's joints are known "
    "(the joint move into each pass); speeds capped by the arm's Cartesian speed limit; no "
    "settling, I/O or controller look-ahead time"
)


@dataclass(frozen=True)
class MotionLimits:
    """What an arm can do, as the cycle-time model reads it.

    speed_mm_s, accel_mm_s2: Cartesian (TCP) speed and acceleration limits.
    angular_speed_deg_s, angular_accel_deg_s2: the tool's reorientation limits.
    joint_speed_deg_s, joint_accel_deg_s2: (6,) per joint, the controller's axis order.
    name: the arm they belong to ("nominal" for plans made without one).
    source: where the figures come from (data sheet, chosen value), for the report.
    """

    name: str
    speed_mm_s: float
    accel_mm_s2: float
    angular_speed_deg_s: float
    angular_accel_deg_s2: float
    joint_speed_deg_s: tuple[float, ...]
    joint_accel_deg_s2: tuple[float, ...]
    source: str = ""

    def __post_init__(self) -> None:
        for what in ("speed_mm_s", "accel_mm_s2", "angular_speed_deg_s", "angular_accel_deg_s2"):
            value = getattr(self, what)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"motion limits {self.name}: {what} must be > 0, got {value}")
        for what in ("joint_speed_deg_s", "joint_accel_deg_s2"):
            values = tuple(float(v) for v in getattr(self, what))
            if len(values) != 6 or not all(math.isfinite(v) and v > 0 for v in values):
                raise ValueError(
                    f"motion limits {self.name}: {what} must be 6 numbers > 0, got {values}"
                )
            object.__setattr__(self, what, values)

    def to_json_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "speed_mm_s": self.speed_mm_s,
            "accel_mm_s2": self.accel_mm_s2,
            "angular_speed_deg_s": self.angular_speed_deg_s,
            "angular_accel_deg_s2": self.angular_accel_deg_s2,
            "joint_speed_deg_s": list(self.joint_speed_deg_s),
            "joint_accel_deg_s2": list(self.joint_accel_deg_s2),
            "source": self.source,
        }


# Data sheets give no Cartesian or joint accelerations. 1 m/s² is what the exported programs
# command (export.ExportOptions.accel_mm_s2) and within what 6-axis arms of this size reach
# with a sensor on the flange; joints are taken to reach full speed in 0.5 s.
ACCEL_MM_S2 = 1000.0
JOINT_RAMP_S = 0.5
# Orientation: below KUKA's default $VEL.ORI1 (200°/s) and ABB speeddata's v_ori (500°/s).
ANGULAR_SPEED_DEG_S = 180.0
ANGULAR_ACCEL_DEG_S2 = 360.0


def joint_accels(speeds_deg_s: tuple[float, ...]) -> tuple[float, ...]:
    """Joint accelerations that reach each joint's full speed in `JOINT_RAMP_S`."""
    return tuple(v / JOINT_RAMP_S for v in speeds_deg_s)


NOMINAL = MotionLimits(
    "nominal",
    speed_mm_s=1000.0,
    accel_mm_s2=ACCEL_MM_S2,
    angular_speed_deg_s=ANGULAR_SPEED_DEG_S,
    angular_accel_deg_s2=ANGULAR_ACCEL_DEG_S2,
    joint_speed_deg_s=(180.0,) * 6,
    joint_accel_deg_s2=joint_accels((180.0,) * 6),
    source="a nominal 6-axis arm for plans made without one: TCP 1 m/s and 180°/s joints "
    "(a UR5e's data sheet), 1 m/s², 180°/s reorientation, joints at full speed in 0.5 s",
)


def trapezoid_time_s(distance: Any, speed: Any, accel: Any) -> np.ndarray:
    """Time to travel `distance` from rest to rest at most at `speed` and `accel`:
    d/v + v/a when d ≥ v²/a (cruise reached), else 2·√(d/a) (triangular). Broadcasts."""
    d = np.abs(np.asarray(distance, dtype=np.float64))
    v = np.asarray(speed, dtype=np.float64)
    a = np.asarray(accel, dtype=np.float64)
    cruise = d >= v * v / a
    return np.where(cruise, d / v + v / a, 2.0 * np.sqrt(d / a))


@dataclass(frozen=True, eq=False)  # array fields: == would be ambiguous
class CycleTime:
    """How long the arm takes to fly a trajectory (`CYCLE_TIME_MODEL`), in seconds.

    pass_s: (p,) per scanning run (`trajectory.pass_bounds`: a pass, or a piece of one where
    poses were dropped or the arm reconfigures); swaths: the passes they belong to.
    move_s: (m,) per move (a run of non-scanning segments: between passes or views, before
    the first, after the last). joint_moves: moves into a pass timed by the arm's joints.
    """

    total_s: float
    scanning_s: float
    moving_s: float
    pass_s: np.ndarray
    move_s: np.ndarray
    scan_speed_mm_s: float
    travel_speed_mm_s: float
    joint_moves: int
    swaths: int
    limits: MotionLimits
    axes_s: float = 0.0  # the external axes' own time (the arm waiting on them), in total_s

    @property
    def runs(self) -> int:
        return len(self.pass_s)

    def line(self) -> str:
        """'cycle time 83.4 s (scanning 61.2 s in 42 passes, moving 22.2 s; trapezoidal,
        kr6-r900 limits)': what `plan`, `evaluate` and `export` print."""
        joints = f", {self.joint_moves} joint moves" if self.joint_moves else ""
        joints += f", waiting {self.axes_s:.1f} s on the external axes" if self.axes_s else ""
        runs = f" ({self.runs} runs)" if self.runs != self.swaths else ""
        return (
            f"cycle time {self.total_s:.1f} s (scanning {self.scanning_s:.1f} s in "
            f"{self.swaths} pass{'es' * (self.swaths != 1)}{runs}, moving {self.moving_s:.1f} s"
            f"{joints}; trapezoidal, {self.limits.name} limits)"
        )

    def to_json_dict(self) -> dict[str, Any]:
        return {
            "total_s": self.total_s,
            "scanning_s": self.scanning_s,
            "axes_s": self.axes_s,
            "moving_s": self.moving_s,
            "passes": self.swaths,
            "runs": self.runs,
            "moves": len(self.move_s),
            "joint_moves": self.joint_moves,
            "run_s": [float(t) for t in self.pass_s],
            "move_s": [float(t) for t in self.move_s],
            "scan_speed_mm_s": self.scan_speed_mm_s,
            "travel_speed_mm_s": self.travel_speed_mm_s,
            "limits": self.limits.to_json_dict(),
            "model": CYCLE_TIME_MODEL,
        }


def _joint_bounds(
    joints_rad: np.ndarray | None, n: int, limits: MotionLimits
) -> tuple[np.ndarray, np.ndarray]:
    """(n-1,) each segment's lower bound on its time from its joints (0 where unknown) and
    (n-1,) its rest-to-rest joint move, slowest joint (NaN where unknown); joints_rad as
    `cycle_time`'s."""
    joint_cruise = np.zeros(n - 1)
    joint_trap = np.full(n - 1, np.nan)
    if joints_rad is None:
        return joint_cruise, joint_trap
    q = np.degrees(np.asarray(joints_rad, dtype=np.float64))
    if q.shape != (n, 6):
        raise ValueError(f"joints must be ({n}, 6), got {q.shape}")
    dq = np.abs(np.diff(q, axis=0))
    known = np.all(np.isfinite(dq), axis=1)
    dq = np.where(known[:, None], dq, 0.0)
    speeds = np.asarray(limits.joint_speed_deg_s)
    joint_cruise = (dq / speeds).max(axis=1)
    trap = trapezoid_time_s(dq, speeds, np.asarray(limits.joint_accel_deg_s2)).max(axis=1)
    return joint_cruise, np.where(known, trap, np.nan)


def _move_seconds(
    moving: np.ndarray,
    through: np.ndarray,
    length: np.ndarray,
    turn: np.ndarray,
    joint_cruise: np.ndarray,
    segment_s: np.ndarray,
    travel_v: float,
    accel: float,
    limits: MotionLimits,
) -> np.ndarray:
    """(m,) seconds of each move, a run of the `moving` (n-1,) segments: a stretch blended
    through its targets (`through`, (n,)) one trapezoid at the travel speed plus what its
    rotation or joints need beyond that, a lone segment between two stops its `segment_s`."""
    move_id = np.cumsum(moving & ~np.r_[False, moving[:-1]]) - 1
    # Stretches of a move: a new one starts at each segment whose first target is a stop.
    stretch_id = np.cumsum(moving & ~(through[:-1] & np.r_[False, moving[:-1]])) - 1
    ids = stretch_id[moving]
    n_stretch = int(ids.max()) + 1 if ids.size else 0
    stretch_n = np.bincount(ids, minlength=n_stretch)
    stretch_len = np.bincount(ids, weights=length[moving], minlength=n_stretch)
    behind = np.maximum(turn / limits.angular_speed_deg_s, joint_cruise) - length / travel_v
    stretch_extra = np.bincount(ids, weights=np.maximum(behind, 0.0)[moving], minlength=n_stretch)
    lone = np.bincount(ids, weights=segment_s[moving], minlength=n_stretch)
    stretch_s = np.where(
        stretch_n > 1, trapezoid_time_s(stretch_len, travel_v, accel) + stretch_extra, lone
    )
    stretch_move = np.zeros(n_stretch, dtype=np.intp)
    stretch_move[ids] = move_id[moving]
    return np.bincount(stretch_move, weights=stretch_s, minlength=len(np.unique(move_id[moving])))


def cycle_time(
    traj: Trajectory,
    spec: ScanSpec,
    limits: MotionLimits = NOMINAL,
    joints_rad: np.ndarray | None = None,
    targets: np.ndarray | None = None,
    blended: np.ndarray | None = None,
) -> CycleTime:
    """The time `traj` takes on an arm with `limits` (`CYCLE_TIME_MODEL`): passes at the
    spec's scan speed, moves at its travel speed, both capped by the arm's Cartesian speed.

    joints_rad: (n, 6) the arm's joints at each pose (the reach check's), NaN where none was
    found; with them each pass is entered by a joint move (`pass_entries`) timed by its
    slowest joint, and the joints bound every other segment too.
    targets: increasing indices of the poses a program flies between (a robot program's
    thinned targets, every pass's first and last pose among them); None: every pose.
    blended: (len(targets),) bool, the targets a move blends through without stopping (a
    program's blend radius > 0); None: a move stops at every target.
    """
    start, _ = pass_bounds(traj.scanning, traj.swath)  # the passes as planned
    entry = pass_entries(traj)  # where each is entered by a joint move
    swaths = len(np.unique(traj.swath[traj.scanning]))
    # The program's TCP: its path, not the sensor origin's, is flown at the scan speed.
    poses, scanning = traj.poses @ spec.T_sensor_line, traj.scanning
    if targets is not None:
        keep = np.asarray(targets, dtype=np.intp)
        poses, scanning, start, entry = poses[keep], scanning[keep], start[keep], entry[keep]
        if joints_rad is not None:
            joints_rad = np.asarray(joints_rad, dtype=np.float64)[keep]
    n = len(poses)
    n_pass = int(start.sum())
    scan_v = min(spec.scan_speed_mm_s, limits.speed_mm_s)
    travel_v = min(spec.travel_speed_mm_s, limits.speed_mm_s)
    accel = limits.accel_mm_s2
    if n < 2:
        return CycleTime(
            0.0, 0.0, 0.0, np.zeros(n_pass), np.zeros(0), scan_v, travel_v, 0, swaths, limits
        )
    length = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    turn = rotation_deg(poses)
    # Segment i runs from pose i to pose i+1; it scans if it ends inside a pass.
    in_pass = scanning[1:] & ~start[1:]
    joint_cruise, joint_trap = _joint_bounds(joints_rad, n, limits)
    has_joints = np.isfinite(joint_trap)

    # Moves: between exact stops, a lone segment is the slower of its translation and
    # rotation, or the program's joint move into a pass when the joints are known; a run
    # blended through its targets is one trapezoid, as a pass is (below).
    through = np.zeros(n, dtype=bool)
    if blended is not None:
        through = np.asarray(blended, dtype=bool)
        if through.shape != (n,):
            raise ValueError(f"blended must be ({n},), got {through.shape}")
    cartesian = np.maximum(
        trapezoid_time_s(length, travel_v, accel),
        trapezoid_time_s(turn, limits.angular_speed_deg_s, limits.angular_accel_deg_s2),
    )
    joint_move = ~in_pass & entry[1:] & has_joints
    segment_s = np.where(
        joint_move, joint_trap, np.where(has_joints, np.fmax(cartesian, joint_trap), cartesian)
    )
    move_s = _move_seconds(
        ~in_pass, through, length, turn, joint_cruise, segment_s, travel_v, accel, limits
    )

    # Passes: one trapezoid over the pass's length, plus whatever a segment's rotation or
    # joints need beyond its share at the scan speed.
    pass_id = (np.cumsum(start) - 1)[1:]
    behind = np.maximum(turn / limits.angular_speed_deg_s, joint_cruise) - length / scan_v
    extra = np.maximum(behind, 0.0)
    pass_len = np.bincount(pass_id[in_pass], weights=length[in_pass], minlength=n_pass)
    pass_extra = np.bincount(pass_id[in_pass], weights=extra[in_pass], minlength=n_pass)
    pass_s = trapezoid_time_s(pass_len, scan_v, accel) + pass_extra

    scanning_s, moving_s = float(pass_s.sum()), float(move_s.sum())
    return CycleTime(
        total_s=scanning_s + moving_s,
        scanning_s=scanning_s,
        moving_s=moving_s,
        pass_s=pass_s,
        move_s=move_s,
        scan_speed_mm_s=scan_v,
        travel_speed_mm_s=travel_v,
        joint_moves=int(joint_move.sum()),
        swaths=swaths,
        limits=limits,
    )


def view_seconds(traj: Trajectory, spec: ScanSpec, entry_mm: float) -> float:
    """About what a view's raster adds to a cycle (`traj`, the view alone): its passes and
    moves blended through every pose, at nominal limits, and a move of `entry_mm` into it
    from the view before."""
    flown = cycle_time(traj, spec, blended=np.ones(len(traj), dtype=bool)).total_s
    entry = trapezoid_time_s(np.array([entry_mm]), spec.travel_speed_mm_s, NOMINAL.accel_mm_s2)
    return flown + float(entry[0])
