"""How much of a part an arm could hold in spec from its best placement, by its inverse
kinematics: tighter than `reach_bound.py` (which asks only whether the wrist point comes
close enough), to tell a part out of an arm's reach wherever it stands from one `place`
puts in the wrong spot.

A sample counts when some sensor pose that measures it in spec has an IK solution within the
joint limits, with the sensor body clear of the cell: the sensor at the working distance,
its beam tilted from the sample's normal by up to 0.9 of the angle tolerance, turned about
the beam, the sample at the middle or towards either end of the laser line (`in_spec_poses`).
What it leaves out (occlusion of the pose's own rays, the arm's body in the beam, the passes'
continuity) only takes more away from a plan, so, up to that sampling of the in-spec poses
(at the working distance alone, not through the depth window), the share is the most any
plan flies from that placement. At the best
placement the share is judged again with the poses twice as dense (has the sampling
settled?) and with the arm's links kept clear of the part and the table (`links.check_links`,
any branch within the limits).

The placements searched: the arm's shoulder on a grid (`--step` mm) where an arm may stand
(`StandsClear`: beside the table's block or on its top, the column of links that turn with
joint 1 alone clear of the table and the part), the base turned to face the part. A
shoulder position is judged by the IK only while the reach bound there (the share whose
wrist shell it reaches, never below the IK's share) is above the best IK share found, best
first: so the best of the grid is found without judging most of it.

    cd benchmarks && PYTHONPATH=../src python arm_bound.py ../../shared/parts \
        [--only drone,quadrotor] [--robots ur5e,kr6-r900] [--tcp 0,0,90,0,0,0] \
        [--part-pose X,Y,Z,A,B,C: that placement judged, not searched]
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
from reach_bound import (
    Shell,
    Stands,
    _shares,
    bound_arguments,
    judged_parts,
    wrist_reach,
    wrist_shell,
)

from scanplan.core.quantities import ScanSpec
from scanplan.robot.base import Robot, inv_rigid
from scanplan.robot.export.rotations import pose_from_xyzabc
from scanplan.robot.links import check_links, obstacles_for, swept_column
from scanplan.robot.nearest_joints import fit_limits
from scanplan.robot.presets import get_robot
from scanplan.world.capsule_collision import CellObstacles

_SAMPLES = 800  # visible samples judged (a random subset, the same for every placement)
_CHUNK = 50_000  # poses per inverse-kinematics call


def _frames(beam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (k, 3) across each beam (k, 3)."""
    side = np.cross(beam, [1.0, 0.0, 0.0])
    flat = np.linalg.norm(side, axis=-1) < 1e-6
    side[flat] = np.cross(beam[flat], [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side, axis=-1, keepdims=True)
    return side, np.cross(beam, side)


def in_spec_poses(
    points: np.ndarray, normals: np.ndarray, spec: ScanSpec, fine: int = 0
) -> np.ndarray:
    """(k, m, 4, 4) sensor poses (part frame) that measure each point (k, 3) with outward
    normal (k, 3) in spec: beam tilts 0, 0.45 and 0.9 of the angle tolerance (8 ways round),
    8 turns about the beam, the point at the line's middle or 0.3 of its width either side;
    `fine`: tilts in quarters up to 0.95, 16 ways round, 16 turns, 5 places on the line."""
    n = -np.asarray(normals, float)
    s, t = _frames(n)
    ways, turns = (16, 16) if fine else (8, 8)
    tilts = np.array([0, 0.25, 0.5, 0.75, 0.95] if fine else [0, 0.45, 0.9]) * spec.tol_angle_rad
    width = spec.sensor.line_width_mm
    along = np.array([-0.4, -0.2, 0, 0.2, 0.4] if fine else [-0.3, 0, 0.3]) * width
    out = []
    for tilt in tilts:
        for way in np.arange(ways if tilt > 0 else 1) * (2 * np.pi / ways):
            d = math.cos(way) * s + math.sin(way) * t
            beam = math.cos(tilt) * n + math.sin(tilt) * d
            a, b = _frames(beam)
            for turn in np.arange(turns) * (2 * np.pi / turns):
                x = math.cos(turn) * a + math.sin(turn) * b
                for u in along:
                    T = np.broadcast_to(np.eye(4), (len(points), 4, 4)).copy()
                    T[:, :3, 0], T[:, :3, 1], T[:, :3, 2] = x, np.cross(beam, x), beam
                    T[:, :3, 3] = points - spec.working_distance_mm * beam - u * x
                    out.append(T)
    return np.stack(out, 1)


def base_facing(robot: Robot, shoulder_in_part: np.ndarray, towards: np.ndarray) -> np.ndarray:
    """T_base_part (4, 4) of the upright arm whose shoulder is at `shoulder_in_part` (3,),
    turned so its first joint's zero faces `towards` (3,) (the part's middle)."""
    yaw = math.atan2(*(towards[:2] - shoulder_in_part[:2])[::-1])
    c, s = math.cos(yaw), math.sin(yaw)
    B = np.eye(4)
    B[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    B[:3, 3] = shoulder_in_part - B[:3, :3] @ wrist_reach(robot).shoulder
    return inv_rigid(B)


def held(
    robot: Robot,
    T_base_part: np.ndarray,
    poses: np.ndarray,
    inv_tcp: np.ndarray,
    obstacles: CellObstacles | None = None,
) -> np.ndarray:
    """(k,) whether some pose of each sample's (k, m, 4, 4) has an IK solution within the
    joint limits (and, with `obstacles`, its links clear of the cell by the quick, slightly
    cautious verdict of `links.check_links`). The poses are tried a few at a time, each
    sample's only until one holds it."""
    k, m = poses.shape[:2]
    out = np.zeros(k, bool)
    per = max(1, _CHUNK // max(k, 1))
    for lo in range(0, m, per):
        left = np.flatnonzero(~out)
        if not len(left):
            break
        flat = poses[left, lo : lo + per].reshape(-1, 4, 4)
        q = robot.inverse(T_base_part @ flat @ inv_tcp)
        q, inside = fit_limits(q, robot.joint_limits)
        inside &= ~np.isnan(q).any(axis=-1)
        if obstacles is not None:
            for branch in range(q.shape[1]):
                at = np.flatnonzero(inside[:, branch])
                if len(at):
                    links = check_links(robot, q[at, branch], obstacles, T_base_part, exact=False)
                    inside[at[links.colliding], branch] = False
        out[left] = inside.any(axis=1).reshape(len(left), -1).any(axis=1)
    return out


@dataclass(frozen=True)
class Judge:
    """The share of the surface an arm holds (`held`) with its shoulder at a point, its base
    facing the samples' `middle`; `share`: the samples' share of the surface."""

    robot: Robot
    poses: np.ndarray
    inv_tcp: np.ndarray
    middle: np.ndarray
    share: float

    def __call__(self, shoulder: np.ndarray, obstacles: CellObstacles | None = None) -> float:
        return self.at(base_facing(self.robot, shoulder, self.middle), obstacles)

    def at(self, T_base_part: np.ndarray, obstacles: CellObstacles | None = None) -> float:
        """The share held with the part at `T_base_part` (4, 4) in the arm's base."""
        ok = held(self.robot, T_base_part, self.poses, self.inv_tcp, obstacles)
        return float(ok.mean()) * self.share


@dataclass(frozen=True)
class StandsClear:
    """Where an arm may stand, for the bound: its column (the links that turn with joint 1
    alone, swept about the vertical: `links.swept_column`) clear of the table as
    `reach_bound.Stands` has it (given no footprint margin) and clear of the part's surface
    `points` (part frame). Kept no clearance away, the other links unchecked:
    looser than `place`, so the bound holds for wherever it may put the arm."""

    stands: Stands
    points: np.ndarray
    shoulder_up_mm: float  # the shoulder above the base frame
    column: tuple[float, float, float]  # its radius, lowest and highest point over the base

    @property
    def on_top_z(self) -> tuple[float, float]:
        return self.stands.on_top_z

    def holds(self, shoulders: np.ndarray) -> np.ndarray:
        """(c,) whether an upright arm can stand with its shoulder at each of (c, 3)."""
        ok = self.stands.holds(shoulders)
        radius, low, high = self.column
        z = self.points[:, 2]
        at = np.flatnonzero(ok)
        for lo in range(0, len(at), 128):
            some = at[lo : lo + 128]
            base = shoulders[some, 2, None] - self.shoulder_up_mm
            near = np.linalg.norm(shoulders[some, None, :2] - self.points[None, :, :2], axis=-1)
            inside = (near < radius) & (z >= base + low) & (z <= base + high)
            ok[some[inside.any(axis=1)]] = False
        return ok


def best_shoulder(judge: Judge, pts, nrm, shell: Shell, reach: float, stands: StandsClear, step):
    """The shoulder position with the most samples held: the best of a `step` grid, judged
    best first by the reach bound there until that bound is below the best found; then the
    grid half as fine about it. Returns (share, shoulder, the reach bound there, judged)."""
    grow = reach + shell.far_mm
    lo, hi = pts.min(axis=0) - grow, pts.max(axis=0) + grow
    axes = [np.arange(a, b + step, step) for a, b in zip(lo, hi, strict=True)]
    # Standing on the table's top, the shoulder is within a few millimetres of one height,
    # which the grid's heights would seldom hit.
    axes[2] = np.union1d(axes[2], np.mean(stands.on_top_z))
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    grid = grid[stands.holds(grid)]
    upper, _ = _shares(grid, pts, nrm, shell, (reach, reach))
    best, best_at, best_upper, judged = 0.0, np.full(3, np.nan), 0.0, 0
    for i in np.argsort(-upper):
        if upper[i] * judge.share <= best:
            break
        got = judge(grid[i])
        judged += 1
        if got > best:
            best, best_at, best_upper = got, grid[i], float(upper[i]) * judge.share
    if not judged:
        return best, best_at, best_upper, judged
    offsets = np.stack(np.meshgrid(*[[-0.5, 0.0, 0.5]] * 3, indexing="ij"), -1).reshape(-1, 3)
    near = best_at + offsets[np.abs(offsets).sum(axis=1) > 0] * step
    if abs(best_at[2] - np.mean(stands.on_top_z)) < 1e-6:  # on the top: stays at its height
        near = near[np.abs(near[:, 2] - best_at[2]) < 1e-6]
    for at in near[stands.holds(near)]:
        got = judge(at)
        judged += 1
        if got > best:
            best, best_at = got, at
    return best, best_at, best_upper, judged


def main() -> None:
    ap = bound_arguments()
    ap.add_argument("--step", type=float, default=50.0, help="the shoulder grid's step, mm")
    ap.add_argument(
        "--part-pose", default="", help="judge this placement only (x,y,z mm, A,B,C deg)"
    )
    args = ap.parse_args()
    spec = ScanSpec()
    inv_tcp = inv_rigid(pose_from_xyzabc(float(v) for v in args.tcp.split(",")))
    print(
        "part | arm | ceiling | reach bound | IK bound | finer poses | with links | shoulder "
        "| judged (s)"
    )
    print("---|---|---|---|---|---|---|---|---")
    for case in judged_parts(args.parts_dir, args.only, spec):
        part, surface, seen, normals = case.part, case.surface, case.seen, case.normals
        cell, block, slack = case.cell, case.block, case.slack_mm
        pick = np.flatnonzero(seen)
        pick = np.sort(np.random.default_rng(0).choice(pick, min(_SAMPLES, len(pick)), False))
        pts, nrm = surface.points[pick], normals[pick]
        middle = (pts.min(axis=0) + pts.max(axis=0)) / 2
        obstacles = obstacles_for(part, cell, spec.sensor, spec.clearance_mm)
        poses = {fine: _clear(in_spec_poses(pts, nrm, spec, fine), obstacles) for fine in (0, 1)}
        for arm in args.robots.split(","):
            robot = get_robot(arm)
            wrist = wrist_reach(robot)
            start = time.perf_counter()
            beside = Stands.of(robot, wrist, block, part.bounds, spec.clearance_mm)
            stands = StandsClear(
                # Anywhere its column clears the table and the part (`_gap` > -1: always).
                replace(beside, sweep_mm=-1.0),
                surface.points[np.random.default_rng(1).permutation(len(surface.points))[:30_000]],
                float(wrist.shoulder[2]),
                swept_column(robot),
            )
            shell = wrist_shell(spec, inv_rigid(inv_tcp), wrist)
            judge = Judge(robot, poses[0], inv_tcp, middle, float(seen.mean()))
            if args.part_pose:  # this placement only: the reach bound is not searched
                T = pose_from_xyzabc(float(v) for v in args.part_pose.split(","))
                found, upper, judged = judge.at(T), float("nan"), 1
                at = (inv_rigid(T) @ np.r_[wrist.shoulder, 1.0])[:3]
            else:
                reach = wrist.radius_mm + slack
                found, at, upper, judged = best_shoulder(
                    judge, pts, nrm, shell, reach, stands, args.step
                )
                T = base_facing(robot, at, middle)
            finer = replace(judge, poses=poses[1]).at(T)
            linked = judge.at(T, obstacles)
            print(
                f"{part.name} | {arm} | {seen.mean():.3f} | {upper:.3f} | {found:.3f} | "
                f"{finer:.3f} | {linked:.3f} | {np.round(at).astype(int).tolist()} | {judged} "
                f"({time.perf_counter() - start:.0f})",
                flush=True,
            )


def _clear(poses: np.ndarray, obstacles: CellObstacles) -> np.ndarray:
    """`poses` (k, m, 4, 4), NaN where the sensor body comes into the cell: they hold
    nothing wherever the arm stands."""
    clear = obstacles.sensor_clear(poses.reshape(-1, 4, 4)).reshape(poses.shape[:2])
    return np.where(clear[..., None, None], poses, np.nan)


if __name__ == "__main__":
    main()
