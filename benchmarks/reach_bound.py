"""How much of a part an arm standing beside its table could hold in spec from any
placement, by its reach alone: an upper bound, to tell whether a part is out of an arm's
reach wherever it stands (then only a positioner helps) or whether a better placement may
exist.

A point in spec was measured from depth W_d +- tol within the fan, the sensor's axis within
the angle tolerance of the point's normal. The arm's wrist point (an OPW arm's wrist centre;
a UR's wrist-3 origin, `wrist_reach`) sits still in the sensor's frame (through the TCP), so
for each surface point it lies in a shell: between two distances from the point, within a
cone about its normal (`wrist_shell`). Whatever its joints, the wrist point is at most
`WristReach.radius_mm` from a fixed shoulder point on the first joint's axis (checked here
against the forward kinematics); the joint limits, the wrist's orientation, the links and
the table only take more away. So from a placement the arm holds in spec at most the samples
whose shell comes that close to its shoulder; the bound is the most of them any shoulder
position the arm can stand at reaches (beside the table's block or on its top, its column
clear, as `links.column_clear` lets `place` put it), found by branch and bound over shoulder
positions (a cell of positions is dropped when its share, reach grown by half its diagonal,
cannot beat the best share found at a cell's centre). The samples are `evaluate`'s (256
columns) on the hemisphere surface, counted only where the visibility ceiling sees them.

    cd benchmarks && PYTHONPATH=../src python reach_bound.py ../../shared/parts \
        [--only drone,quadrotor] [--robots ur5e,kr6-r900] [--tcp 0,0,90,0,0,0]
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from compare_views import PARTS  # the shared parts and their units (benchmarks/)

from scanplan.core.quantities import ScanSpec
from scanplan.judging.evaluation import coverage_spacing_mm, in_spec_radius_mm
from scanplan.robot.base import Robot, inv_rigid
from scanplan.robot.export.rotations import pose_from_xyzabc
from scanplan.robot.links import ON_TABLE_MM, column_clear, swept_column
from scanplan.robot.opw import OPWRobot
from scanplan.robot.presets import get_robot
from scanplan.robot.ur import URModel
from scanplan.world.cell import Cell
from scanplan.world.part import Part, load_part
from scanplan.world.surface import (
    VisibleSurface,
    hemisphere_visible_samples,
    oriented_normals,
    reachable_samples,
)

# The branch and bound: first cells this wide (mm), halved until this fine, or until the
# bound is within this share of the best placement found.
_FIRST_CELL_MM = 200.0
_FINEST_CELL_MM = 12.5
_CLOSE_ENOUGH = 0.005
_PAIRS_PER_CHUNK = 4_000_000  # shoulder positions x samples per distance computation


@dataclass(frozen=True)
class WristReach:
    """The arm's wrist point: `in_flange` (3,) in the flange frame, at most `radius_mm` from
    `shoulder` (3,), a point on the first joint's axis in the base frame, for any joints."""

    shoulder: np.ndarray
    radius_mm: float
    in_flange: np.ndarray


def wrist_reach(robot: Robot) -> WristReach:
    """The wrist point of an OPW arm (its wrist centre, c4 behind the flange; the shoulder
    at height c1: the centre lies within c2 + hypot(a2, c3) of the circle of radius a1
    there, offset b sideways) or of a UR (d6 behind the flange; the shoulder at d1: the arm
    plane's reach |a2| + |a3| + d5, offset d4 sideways). Raises TypeError for another
    kind of arm."""
    if isinstance(robot, OPWRobot):
        in_flange = (inv_rigid(robot.flange) @ np.array([0.0, 0.0, -robot.c4, 1.0]))[:3]
        shoulder = (robot.base @ np.array([0.0, 0.0, robot.c1, 1.0]))[:3]
        planar = robot.c2 + math.hypot(robot.a2, robot.c3) + abs(robot.a1)
        return WristReach(shoulder, math.hypot(planar, robot.b), in_flange)
    if isinstance(robot, URModel):
        planar = abs(robot.a2) + abs(robot.a3) + robot.d5
        return WristReach(
            np.array([0.0, 0.0, robot.d1]),
            math.hypot(planar, robot.d4),
            np.array([0.0, 0.0, -robot.d6]),
        )
    raise TypeError(f"no reach model for arm {robot.name}")


@dataclass(frozen=True)
class Shell:
    """Where the wrist point can be for a point measured in spec: `near_mm`..`far_mm` from
    the point, within `half_angle_rad` of its normal."""

    near_mm: float
    far_mm: float
    half_angle_rad: float


def wrist_shell(scan_spec: ScanSpec, T_flange_sensor: np.ndarray, wrist: WristReach) -> Shell:
    """The shell of the wrist point for the sensor on `T_flange_sensor` (4, 4): the point
    is at (x, 0, z) in the sensor's frame, z within the depth tolerance, x within the fan
    there, so the wrist point is the fixed sensor-frame point w minus that; its distance
    and its angle to the sensor's axis are bounded on a fine grid of (x, z), widened by
    the grid's step; the axis is within the angle tolerance of the normal."""
    sensor = scan_spec.sensor
    w = (inv_rigid(np.asarray(T_flange_sensor, float)) @ np.r_[wrist.in_flange, 1.0])[:3]
    wd, tol = scan_spec.working_distance_mm, scan_spec.tolerance_mm
    z = np.linspace(wd - tol, wd + tol, 21)
    half_fan = sensor.line_width_mm / 2 / wd  # tan of the fan's half angle
    u = np.linspace(-1.0, 1.0, 201)
    x = u[None, :] * (half_fan * z[:, None])
    zz = np.broadcast_to(z[:, None], x.shape)
    q = np.stack([w[0] - x, np.full_like(x, w[1]), w[2] - zz], -1)  # wrist less the point
    length = np.linalg.norm(q, axis=-1)
    off_axis = np.arccos(np.clip(-q[..., 2] / length, -1.0, 1.0))  # from -z_s: towards it
    step = math.hypot(2 * tol / 20, 2 * half_fan * (wd + tol) / 200)
    near = max(float(length.min()) - step, 0.0)
    return Shell(
        near,
        float(length.max()) + step,
        scan_spec.tol_angle_rad + float(off_axis.max()) + step / max(near, 1.0),
    )


def _shell_distance(shoulders: np.ndarray, points: np.ndarray, normals: np.ndarray, shell: Shell):
    """(c, k) the distance from each shoulder position (c, 3) to each point's shell."""
    v = shoulders[:, None, :] - points[None, :, :]
    d = np.linalg.norm(v, axis=-1)
    cos_phi = np.einsum("cki,ki->ck", v, normals) / np.maximum(d, 1e-9)
    phi = np.arccos(np.clip(cos_phi, -1.0, 1.0))
    cos_gap = np.cos(np.maximum(phi - shell.half_angle_rad, 0.0))
    t = np.clip(d * cos_gap, shell.near_mm, shell.far_mm)
    return np.sqrt(np.maximum(d * d + t * t - 2.0 * d * t * cos_gap, 0.0))


def _shares(
    centres: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    shell: Shell,
    radii: tuple[float, float],
) -> tuple[np.ndarray, np.ndarray]:
    """(c,) x2: the share of the points whose shell lies within each of `radii` of the
    shoulder at each centre, over `len(points)`."""
    out = (np.zeros(len(centres)), np.zeros(len(centres)))
    step = max(1, _PAIRS_PER_CHUNK // max(len(points), 1))
    for lo in range(0, len(centres), step):
        dist = _shell_distance(centres[lo : lo + step], points, normals, shell)
        for share, radius in zip(out, radii, strict=True):
            share[lo : lo + step] = (dist <= radius).mean(axis=1)
    return out


@dataclass(frozen=True)
class ReachBound:
    """`bound`: no shoulder position the arm can stand at holds more of the samples in reach;
    `best`: the share at the best position found (`shoulder_mm`, part frame), which the
    bound is within `_CLOSE_ENOUGH` of or the search's finest cell."""

    bound: float
    best: float
    shoulder_mm: np.ndarray


def _gap(xy: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(...) the horizontal distance from points (..., 2) to the rectangle lo..hi."""
    return np.linalg.norm(np.maximum(np.maximum(lo - xy, xy - hi), 0.0), axis=-1)


@dataclass(frozen=True)
class Stands:
    """Where the arm's shoulder can be, in the part frame: where `links.column_clear` lets
    the upright arm stand (its column, swept about the first axis, clear beside the table
    `block`, or on its top), its column clear of the part's footprint `part_xy` too (the
    sweep `sweep_mm` with the clearance). `on_top_z`: the shoulder heights on the top."""

    robot: Robot
    shoulder: np.ndarray
    block: tuple[np.ndarray, np.ndarray]
    part_xy: tuple[np.ndarray, np.ndarray]
    clearance_mm: float
    sweep_mm: float
    on_top_z: tuple[float, float]

    @classmethod
    def of(cls, robot: Robot, wrist: WristReach, block, part_bounds, clearance_mm: float):
        sweep, z_lo, _ = swept_column(robot)  # as column_clear sweeps it
        top, up = float(block[1][2]), float(wrist.shoulder[2])
        return cls(
            robot,
            wrist.shoulder,
            (np.asarray(block[0], float), np.asarray(block[1], float)),
            (np.asarray(part_bounds[0][:2], float), np.asarray(part_bounds[1][:2], float)),
            clearance_mm,
            sweep + clearance_mm,
            (top + clearance_mm - z_lo + up, top + ON_TABLE_MM + up),
        )

    def holds(self, shoulders: np.ndarray) -> np.ndarray:
        """(c,) whether an arm can stand with its shoulder at each of (c, 3)."""
        T_base_part = np.broadcast_to(np.eye(4), (len(shoulders), 4, 4)).copy()
        T_base_part[:, :3, 3] = self.shoulder - shoulders  # the part in the upright base
        clear = column_clear(self.robot, T_base_part, self.block, self.clearance_mm)
        return clear & (_gap(shoulders[:, :2], *self.part_xy) > self.sweep_mm)

    def may_hold(self, centres: np.ndarray, half: float) -> np.ndarray:
        """(c,) False only where no shoulder position in the cube of half-size `half` about
        each centre is one an arm can stand at (the rounded rectangles are convex: a
        square whose corners lie within one lies within it)."""
        corners = centres[:, None, :2] + half * np.array([[-1, -1], [-1, 1], [1, -1], [1, 1]])
        over_block = (_gap(corners, self.block[0][:2], self.block[1][:2]) <= self.sweep_mm).all(1)
        over_part = (_gap(corners, *self.part_xy) <= self.sweep_mm).all(axis=1)
        lo, hi = self.on_top_z
        slab = (centres[:, 2] + half >= lo) & (centres[:, 2] - half <= hi)
        return ~over_block | (slab & ~over_part)


def reach_bound(
    points: np.ndarray,
    normals: np.ndarray,
    counted: np.ndarray,
    shell: Shell,
    wrist: WristReach,
    stands: Stands,
    slack_mm: float = 0.0,
) -> ReachBound:
    """The most of the samples `points` (k, 3) with outward `normals` (k, 3) an arm's wrist
    can serve from any shoulder position it can stand at (`stands`), counting only the
    samples `counted` marks (the visible ones) over all k. slack_mm: how far the point
    measured may lie from a sample it holds in spec (the in-spec radius). Shoulder heights
    run from the lowest sample less the reach to the highest plus it."""
    pts = np.asarray(points, float)[counted]
    nrm = np.asarray(normals, float)[counted]
    share = len(pts) / max(len(points), 1)
    reach = wrist.radius_mm + slack_mm
    if not len(pts):
        return ReachBound(0.0, 0.0, np.full(3, np.nan))
    grow = reach + shell.far_mm
    lo, hi = pts.min(axis=0) - grow, pts.max(axis=0) + grow
    size = _FIRST_CELL_MM
    axes = [np.arange(a + size / 2, b + size / 2, size) for a, b in zip(lo, hi, strict=True)]
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    corners = np.stack(np.meshgrid(*[[-0.5, 0.5]] * 3, indexing="ij"), -1).reshape(-1, 3)
    best, best_at = 0.0, np.full(3, np.nan)
    while True:
        half = size / 2
        centres = centres[stands.may_hold(centres, half)]
        if not len(centres):
            return ReachBound(best, best, best_at)
        upper, at = _shares(centres, pts, nrm, shell, (reach + half * math.sqrt(3), reach))
        upper, at = upper * share, at * share
        standing = stands.holds(centres)
        if standing.any() and at[standing].max() > best:
            pick = np.flatnonzero(standing)[np.argmax(at[standing])]
            best, best_at = float(at[pick]), centres[pick]
        bound = float(upper.max())
        if size <= _FINEST_CELL_MM or bound - best <= _CLOSE_ENOUGH:
            return ReachBound(max(bound, best), best, best_at)
        size = half
        centres = (centres[upper > best][:, None, :] + corners * size).reshape(-1, 3)


def checked_radius(robot: Robot, wrist: WristReach, samples: int = 200_000) -> float:
    """The farthest the wrist point gets from the shoulder over random joints (the forward
    kinematics, limits ignored), over `wrist.radius_mm`: at most 1, and close to it."""
    q = np.random.default_rng(0).uniform(-np.pi, np.pi, (samples, 6))
    T = robot.forward(q)
    at = T[:, :3, 3] + np.einsum("nij,j->ni", T[:, :3, :3], wrist.in_flange)
    return float(np.linalg.norm(at - wrist.shoulder, axis=1).max()) / wrist.radius_mm


@dataclass(frozen=True)
class Judged:
    """A part as the bounds judge it: its samples seen from the upper hemisphere at 256
    columns (`surface`, `evaluate`'s), those the visibility ceiling sees (`seen`), their
    outward `normals`, the table's `block` under it, and `slack_mm`: how far the point
    measured may lie from a sample it holds in spec (the in-spec radius)."""

    part: Part
    surface: VisibleSurface
    seen: np.ndarray
    normals: np.ndarray
    cell: Cell
    block: tuple[np.ndarray, np.ndarray]
    slack_mm: float


def judged_parts(parts_dir: str, only: str, spec: ScanSpec) -> Iterator[Judged]:
    """The built-in drone and door and the shared parts in `parts_dir` whose name holds one
    of `only`'s comma-separated names (all if empty), each `Judged`."""
    sensor = spec.sensor.with_points(256)
    parts = {"drone": "mm", "door": "mm"}
    parts |= {str(Path(parts_dir) / n): u for n, u in PARTS.items()}
    for name, units in parts.items():
        if only and not any(o in name for o in only.split(",")):
            continue
        part = load_part(name, units)
        surface = hemisphere_visible_samples(part, coverage_spacing_mm(sensor), 0)
        cell = Cell.around(part)
        seen = reachable_samples(cell.occluding(part), surface, spec.tol_angle_rad)
        block = cell.table_block(part)
        assert block is not None
        pitch = sensor.line_width_mm / (sensor.points_per_profile - 1)
        normals = oriented_normals(part)[surface.faces]
        yield Judged(part, surface, seen, normals, cell, block, in_spec_radius_mm(spec, pitch))


def bound_arguments() -> argparse.ArgumentParser:
    """The arguments both bounds take: the shared parts' folder, which parts and arms, the
    sensor's mount on the flange."""
    ap = argparse.ArgumentParser()
    ap.add_argument("parts_dir", nargs="?", default="../shared/parts")
    ap.add_argument("--only", default="", help="parts whose name contains this (a,b: any)")
    ap.add_argument("--robots", default="ur5e,kr6-r900,irb2400")
    ap.add_argument("--tcp", default="0,0,90,0,0,0", help="x,y,z mm, A,B,C deg (ZYX)")
    return ap


def main() -> None:
    args = bound_arguments().parse_args()
    spec = ScanSpec()
    tcp = pose_from_xyzabc(float(v) for v in args.tcp.split(","))
    print("part | arm | wrist radius mm (FK max / formula) | ceiling | bound | best | shoulder")
    print("---|---|---|---|---|---|---")
    for judged in judged_parts(args.parts_dir, args.only, spec):
        part, surface, seen, normals = judged.part, judged.surface, judged.seen, judged.normals
        block, slack = judged.block, judged.slack_mm
        for arm in args.robots.split(","):
            robot = get_robot(arm)
            wrist = wrist_reach(robot)
            start = time.perf_counter()
            stands = Stands.of(robot, wrist, block, part.bounds, spec.clearance_mm)
            shell = wrist_shell(spec, tcp, wrist)
            found = reach_bound(surface.points, normals, seen, shell, wrist, stands, slack)
            print(
                f"{part.name} | {arm} | {wrist.radius_mm:.0f} ({checked_radius(robot, wrist):.4f})"
                f" | {seen.mean():.3f} | {found.bound:.3f} | {found.best:.3f} | "
                f"{np.round(found.shoulder_mm).astype(int).tolist()} "
                f"({time.perf_counter() - start:.0f} s)",
                flush=True,
            )


if __name__ == "__main__":
    main()
