"""The Trajectory type every planner produces: sensor poses in the part frame
(`T_part_sensor`, millimetres), the pass each belongs to and whether it scans. Its files are
`plan_file`'s."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

# The most a move's sensor poses are apart: each is checked, so every place the body passes
# is. A plan's longer straight step is where a fit gave up poses of a move after planning
# (`robot.straight_moves` checks the way between).
MOVE_STEP_MM = 20.0


@dataclass(frozen=True)
class Trajectory:
    """A sensor path over a part.

    poses:    (n, 4, 4) float64, `T_part_sensor` in mm.
    swath:    (n,) int, index of the pass each pose belongs to (transitions carry the index of
              the pass they lead to).
    scanning: (n,) bool, True where the sensor records profiles.
    plan_time_s: wall time the planner took.
    planner:  name of the planner that made it.
    external: (n, k) float64 or None: the external axes' values at each pose (a turntable's
              angle in degrees, a track's position in mm, in the order of the arm record's
              `external_axes`); None: the arm alone.
    meta:     extra records; those named in `plan_records.FILE_RECORDS` go into the files:
              `context` (what it was planned under, `context.PlanContext`), `views` (per
              view its `axis` and its block of swath indices `first_swath..last_swath`)
              and `robot` (the arm's record).
    """

    poses: np.ndarray
    swath: np.ndarray
    scanning: np.ndarray
    plan_time_s: float = 0.0
    planner: str = ""
    meta: dict = field(default_factory=dict)
    external: np.ndarray | None = None

    def __post_init__(self) -> None:
        poses = np.asarray(self.poses, dtype=np.float64)
        if poses.ndim != 3 or poses.shape[1:] != (4, 4):
            raise ValueError(f"trajectory poses must be (n, 4, 4), got {poses.shape}")
        n = len(poses)
        swath = _swath_indices(self.swath)
        scanning = np.asarray(self.scanning, dtype=bool).reshape(-1)
        if len(swath) != n or len(scanning) != n:
            raise ValueError(
                f"trajectory has {n} poses but {len(swath)} swath and {len(scanning)} flags"
            )
        if not np.isfinite(poses).all():
            raise ValueError("trajectory has non-finite poses")
        if not math.isfinite(self.plan_time_s):
            raise ValueError(f"trajectory plan_time_s must be finite, got {self.plan_time_s}")
        if self.external is not None:
            external = np.asarray(self.external, dtype=np.float64)
            if external.ndim != 2 or len(external) != n or not np.isfinite(external).all():
                raise ValueError(
                    f"trajectory external axis values must be finite, ({n}, k), got "
                    f"{external.shape}"
                )
            object.__setattr__(self, "external", external)
        object.__setattr__(self, "poses", poses)
        object.__setattr__(self, "swath", swath)
        object.__setattr__(self, "scanning", scanning)

    def __len__(self) -> int:
        return len(self.poses)

    @property
    def positions_mm(self) -> np.ndarray:
        """(n, 3) sensor origins in the part frame."""
        return self.poses[:, :3, 3]

    @property
    def quaternions_wxyz(self) -> np.ndarray:
        """(n, 4) unit quaternions, scalar first."""
        xyzw = Rotation.from_matrix(self.poses[:, :3, :3]).as_quat()
        return np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)

    @property
    def scan_poses(self) -> np.ndarray:
        """(m, 4, 4) the poses where the sensor records."""
        return self.poses[self.scanning]

    def subset(self, keep: np.ndarray, swath: np.ndarray | None = None) -> Trajectory:
        """The poses where `keep` (n,) is True, with the pass indices `swath` (n,) if given
        (renumbered ones), else their own; times and records unchanged, but for where an
        arm record says passes are entered (by pose index: of the whole plan, not of this)."""
        swath = self.swath if swath is None else swath
        external = None if self.external is None else self.external[keep]
        meta = self.meta
        robot = meta.get("robot")
        if isinstance(robot, dict) and "pass_entry_joints_deg" in robot:
            rest = {k: v for k, v in robot.items() if k != "pass_entry_joints_deg"}
            meta = meta | {"robot": rest}
        return replace(
            self,
            poses=self.poses[keep],
            swath=swath[keep],
            scanning=self.scanning[keep],
            external=external,
            meta=meta,
        )

    def path_length_mm(self, scanning_only: bool = False) -> float:
        p = self.positions_mm[self.scanning] if scanning_only else self.positions_mm
        if len(p) < 2:
            return 0.0
        return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())

    @staticmethod
    def concatenate(parts: list[Trajectory], planner: str = "") -> Trajectory:
        if not parts:
            raise ValueError("cannot concatenate an empty list of trajectories")
        with_axes = [t.external is not None for t in parts]
        if any(with_axes) and not all(with_axes):
            raise ValueError("cannot concatenate trajectories with and without external axes")
        return Trajectory(
            poses=np.concatenate([t.poses for t in parts]),
            swath=np.concatenate([t.swath for t in parts]),
            scanning=np.concatenate([t.scanning for t in parts]),
            plan_time_s=float(sum(t.plan_time_s for t in parts)),
            planner=planner or parts[0].planner,
            meta=_sum_counters([t.meta for t in parts]),
            external=(
                np.concatenate([t.external for t in parts if t.external is not None])
                if all(with_axes)
                else None
            ),
        )


def pass_bounds(scanning: np.ndarray, swath: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(start, end) masks of scanning runs (the passes as flown); a run also breaks where the
    swath index changes."""
    s = np.asarray(scanning, dtype=bool)
    new_swath = np.r_[True, swath[1:] != swath[:-1]]
    start = s & (~np.r_[False, s[:-1]] | new_swath)
    end = s & (~np.r_[s[1:], False] | np.r_[new_swath[1:], True])
    return start, end


def lead_tops(traj: Trajectory) -> np.ndarray:
    """(n,) int: for each pass's first pose, the top of the move leading into it (its
    non-scanning poses just before it, which carry its swath index): the via point farthest
    from both the pass before and the pass's own first pose, where an arm reconfigures clear
    of the part rather than beside the surface; the pass's first pose itself when no move
    leads in. -1 at every other pose."""
    start, _ = pass_bounds(traj.scanning, traj.swath)
    top = np.full(len(traj), -1)
    pos = traj.positions_mm
    # Where each run of moves of one swath index begins (a pass's lead-in is such a run).
    moving, swath = ~traj.scanning, traj.swath
    fresh = moving & np.r_[True, traj.scanning[:-1] | (swath[1:] != swath[:-1])]
    run_start = np.maximum.accumulate(np.where(fresh, np.arange(len(traj)), 0))
    for s in np.flatnonzero(start):
        led = s > 0 and moving[s - 1] and swath[s - 1] == swath[s]
        j = int(run_start[s - 1]) if led else s
        top[s] = s
        if j == s:
            continue
        lead = np.arange(j, s)
        clear = np.linalg.norm(pos[lead] - pos[s], axis=1)
        if j > 0:  # and from where the pass before ended
            clear = np.minimum(clear, np.linalg.norm(pos[lead] - pos[j - 1], axis=1))
        top[s] = lead[int(np.argmax(clear))]
    return top


def lead_ins(traj: Trajectory) -> np.ndarray:
    """(n,) bool: the moves into each pass, its swath's poses before its first scanning pose."""
    passes, at = np.unique(traj.swath, return_inverse=True)
    first = np.full(len(passes), len(traj))
    np.minimum.at(first, at[traj.scanning], np.flatnonzero(traj.scanning))
    return ~traj.scanning & (np.arange(len(traj)) < first[at])


def rotation_deg(poses: np.ndarray) -> np.ndarray:
    """(n-1,) angle of the rotation between consecutive poses (n, 4, 4), degrees."""
    R = poses[:, :3, :3]
    trace = np.einsum("nji,nji->n", R[:-1], R[1:])  # trace(R_iᵀ R_i+1)
    return np.degrees(np.arccos(np.clip((trace - 1.0) / 2.0, -1.0, 1.0)))


def half_turns(traj: Trajectory, least_deg: float = 90.0) -> np.ndarray:
    """(n,) bool: the poses whose sensor is turned more than `least_deg` from the pose before
    (a pass turned half a turn about its beam beside a move that is not): an arm turns it
    so in a joint move, not in a linear one."""
    return np.r_[False, rotation_deg(traj.poses) > least_deg]


def pass_entries(traj: Trajectory) -> np.ndarray:
    """(n,) bool: where a program enters a pass by a joint move into the configuration it
    flies the pass on: where the plan's arm record says (`pass_entry_joints_deg`, chosen by
    the fit: a pass's first pose, or the top of the move into it, `lead_tops`, where a joint
    move beside the surface would sweep a link into the part); each pass's first pose for a
    plan that records none."""
    start, _ = pass_bounds(traj.scanning, traj.swath)
    recorded = (traj.meta.get("robot") or {}).get("pass_entry_joints_deg")
    if not isinstance(recorded, dict):
        return start
    entry = np.zeros(len(traj), bool)
    at = [int(k) for k in recorded if str(k).isdigit() and int(k) < len(traj)]
    entry[at] = True
    return entry


INT32 = np.iinfo(np.int32)


def _swath_indices(values: object) -> np.ndarray:
    """(n,) int64 pass indices; refuses what would wrap or round silently (1e20, 0.5)."""
    raw = np.asarray(values).reshape(-1)
    if raw.dtype == bool or not np.issubdtype(raw.dtype, np.number):
        raise ValueError(f"trajectory swath indices must be integers, got {raw.dtype}")
    if not np.issubdtype(raw.dtype, np.integer):
        with np.errstate(invalid="ignore"):
            integral = np.isfinite(raw) & (raw == np.round(raw))
        if not integral.all():
            raise ValueError("trajectory swath indices must be integers")
    if len(raw) and (raw.min() < INT32.min or raw.max() > INT32.max):
        raise ValueError("trajectory swath indices must fit a 32-bit integer")
    return raw.astype(np.int64)


def _sum_counters(metas: list[dict]) -> dict:
    """The integer counters of per-pass metadata (e.g. the rl planner's guard overrides),
    summed over the passes."""
    total: dict[str, int] = {}
    for meta in metas:
        for key, value in meta.items():
            if isinstance(value, int):
                total[key] = total.get(key, 0) + value
    return total


def poses_from_xyz_quat(xyz: np.ndarray, quat_wxyz: np.ndarray) -> np.ndarray:
    """(n, 4, 4) poses from positions and scalar-first quaternions (normalized here)."""
    q = np.asarray(quat_wxyz, dtype=np.float64)
    norms = np.linalg.norm(q, axis=1)
    if np.any(norms < 1e-9):
        raise ValueError("quaternion of zero length")
    xyzw = np.concatenate([q[:, 1:], q[:, :1]], axis=1) / norms[:, None]
    poses = np.tile(np.eye(4), (len(q), 1, 1))
    poses[:, :3, :3] = Rotation.from_quat(xyzw).as_matrix()
    poses[:, :3, 3] = xyz
    return poses
