"""The arm's body: conservative capsules along its links, placed by forward kinematics, and
how close they come to the part, the fixtures and the table.

A link is the segment between two consecutive points of the arm's skeleton (base, shoulder,
elbow, wrist centre, flange; for a UR the origins of its DH frames) with a radius that holds
the maker's casting: `LINK_RADIUS_MM` per preset, from the data sheets' link diameters with
margin; an arm from a file gets a radius scaled from its upper-arm length. The obstacles:
the part's and fixtures' surfaces sampled as points `OBSTACLE_SPACING_MM` apart (a k-d
tree), and the table, a plane the arm stands on beside the part (its base column, the first
link, stands on it); a link is clear when every point of its axis is farther than its radius
plus the clearance from the table and, plus half the sample spacing, from every sample.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from scanplan.robot.base import Robot
from scanplan.robot.opw import OPWRobot
from scanplan.robot.ur import URModel, _dh

# Capsule radii (mm) that hold each preset's links (data-sheet diameters plus ~10 mm).
LINK_RADIUS_MM = {
    "ur3e": 50.0,
    "ur5e": 65.0,
    "ur10e": 80.0,
    "kr6-r900": 75.0,
    "irb2400": 110.0,
    "lrmate200id": 60.0,
}
OBSTACLE_SPACING_MM = 10.0
# Points sampled along a link's axis per radius of its length.
_SAMPLES_PER_RADIUS = 2.0


def skeleton(robot: Robot, q: np.ndarray) -> np.ndarray:
    """(n, k, 3) the skeleton's points in the base frame (mm) for joints q (n, 6)."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 6)
    if isinstance(robot, URModel):
        a, d, alpha = robot.dh
        T = np.broadcast_to(np.eye(4), (len(q), 4, 4))
        points = [T[:, :3, 3]]
        for j in range(6):
            T = T @ _dh(q[:, j], d[j], a[j], alpha[j])
            points.append(T[:, :3, 3])
        return np.stack(points, axis=1)
    if isinstance(robot, OPWRobot):
        return _opw_skeleton(robot, q)
    raise ValueError(f"robot {robot.name}: no link geometry for this kind of arm")


def _opw_skeleton(arm: OPWRobot, q: np.ndarray) -> np.ndarray:
    t = arm._to_opw(q)
    t1, t2, t3 = t[:, 0], t[:, 1], t[:, 2]
    c1, s1 = np.cos(t1), np.sin(t1)

    def turned(x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """A point of the arm's plane (x out, y = b sideways, z up) turned by joint 1."""
        return np.stack([x * c1 - arm.b * s1, x * s1 + arm.b * c1, z + arm.c1], axis=-1)

    zero = np.zeros_like(t1)
    psi3, k = np.arctan2(arm.a2, arm.c3), np.hypot(arm.a2, arm.c3)
    elbow_x = arm.a1 + arm.c2 * np.sin(t2)
    elbow_z = arm.c2 * np.cos(t2)
    wrist_x = elbow_x + k * np.sin(t2 + t3 + psi3)
    wrist_z = elbow_z + k * np.cos(t2 + t3 + psi3)
    points = np.stack(
        [
            np.stack([zero, zero, zero], axis=-1),
            np.stack([zero, zero, zero + arm.c1], axis=-1),
            turned(zero + arm.a1, zero),
            turned(elbow_x, elbow_z),
            turned(wrist_x, wrist_z),
        ],
        axis=1,
    )
    flange = arm.forward(q)[:, :3, 3]
    base = arm.base
    points = points @ base[:3, :3].T + base[:3, 3]
    return np.concatenate([points, flange[:, None]], axis=1)


def link_radius_mm(robot: Robot) -> float:
    if robot.name in LINK_RADIUS_MM:
        return LINK_RADIUS_MM[robot.name]
    if isinstance(robot, OPWRobot):
        return float(np.clip(0.15 * arm_length_mm(robot), 40.0, 150.0))
    return 80.0


def arm_length_mm(robot: OPWRobot) -> float:
    return float(robot.c2 + np.hypot(robot.a2, robot.c3))


@dataclass(frozen=True)
class Obstacles:
    """What the arm must keep clear of: surface samples (a k-d tree of the part's and
    fixtures' faces, in the arm's base frame) and the table, the plane z = table_z_mm of the
    part frame (`T_part_base` away; None: no table)."""

    tree: cKDTree
    T_part_base: np.ndarray
    table_z_mm: float | None

    def distance_mm(self, points: np.ndarray, reach_mm: float) -> np.ndarray:
        """(m,) distance of points (m, 3, base frame) to the nearest obstacle, capped at
        `reach_mm` (negative: below the table)."""
        d, _ = self.tree.query(points, distance_upper_bound=reach_mm, workers=-1)
        d = np.minimum(d, reach_mm) - 0.5 * OBSTACLE_SPACING_MM
        if self.table_z_mm is not None:
            height = points @ self.T_part_base[2, :3] + self.T_part_base[2, 3]
            d = np.minimum(d, height - self.table_z_mm)
        return d


def link_clearance_mm(
    robot: Robot, joints: np.ndarray, obstacles: Obstacles, reach_mm: float = 200.0
) -> np.ndarray:
    """(n,) the least distance between the arm's capsules and the obstacles for joints (n, 6)
    (NaN rows, poses the arm does not reach, give NaN), capped at `reach_mm`; the last link
    ends at the flange, where the sensor (checked on its own) takes over."""
    joints = np.asarray(joints, dtype=np.float64)
    out = np.full(len(joints), np.nan)
    ok = ~np.isnan(joints).any(axis=1)
    if not ok.any():
        return out
    radius = link_radius_mm(robot)
    points = skeleton(robot, joints[ok])  # (n, k, 3)
    # The first link stands on the arm's own mounting: only from the shoulder up.
    a, b = points[:, 1:-1], points[:, 2:]
    length = np.linalg.norm(b - a, axis=-1).max()
    count = max(2, int(np.ceil(_SAMPLES_PER_RADIUS * length / radius)) + 1)
    t = np.linspace(0.0, 1.0, count)
    axis = a[:, :, None] + t[None, None, :, None] * (b - a)[:, :, None]  # (n, k-2, c, 3)
    d = obstacles.distance_mm(axis.reshape(-1, 3), reach_mm + radius)
    out[ok] = d.reshape(len(points), -1).min(axis=1) - radius
    return out


@dataclass(frozen=True, eq=False)
class ObstacleSpec:
    """The obstacles in the part's frame (the part and fixture meshes, the table's height,
    None: no table) and the clearance the arm keeps from them; `placed` puts them in an
    arm's base frame."""

    meshes: tuple[trimesh.Trimesh, ...]
    table_z_mm: float | None
    clearance_mm: float

    @functools.cached_property
    def samples_part(self) -> np.ndarray:
        """(m, 3) the meshes' surfaces, points about `OBSTACLE_SPACING_MM` apart."""
        out = []
        for mesh in self.meshes:
            count = int(np.clip(mesh.area / OBSTACLE_SPACING_MM**2, 1_000, 400_000))
            points, _ = trimesh.sample.sample_surface_even(mesh, count, seed=0)
            out.append(np.vstack([np.asarray(points), np.asarray(mesh.vertices)]))
        return np.vstack(out)

    def placed(self, T_base_part: np.ndarray) -> PlacedObstacles:
        points = self.samples_part @ T_base_part[:3, :3].T + T_base_part[:3, 3]
        obstacles = Obstacles(cKDTree(points), np.linalg.inv(T_base_part), self.table_z_mm)
        return PlacedObstacles(obstacles, self.clearance_mm)

    def on_the_table(self) -> tuple[float, float] | None:
        """The height range of a placement (the part origin's z in the base frame) that
        stands the arm on the part's table: the table plane through the base (None: no
        table, the part is held in the air)."""
        if self.table_z_mm is None:
            return None
        return (-self.table_z_mm, -self.table_z_mm)


@dataclass(frozen=True)
class PlacedObstacles:
    obstacles: Obstacles
    clearance_mm: float


def links_colliding(robot: Robot, joints: np.ndarray, placed: PlacedObstacles) -> np.ndarray:
    """(n,) bool: the arm's links come within the clearance at pose i or on the way to it
    from pose i-1 (joints interpolated halfway); unreachable poses (NaN joints) are not."""
    joints = np.asarray(joints, dtype=np.float64)
    at = link_clearance_mm(robot, joints, placed.obstacles, placed.clearance_mm + 50.0)
    halfway = link_clearance_mm(
        robot, 0.5 * (joints[1:] + joints[:-1]), placed.obstacles, placed.clearance_mm + 50.0
    )
    clear = placed.clearance_mm
    out = at < clear
    out[1:] |= halfway < clear
    return out


def clear_of(robot: Robot, placed: PlacedObstacles) -> Callable[[np.ndarray], np.ndarray]:
    """Joint solutions (k, 6) -> (k,) bool: the links keep the clearance (a reach check's
    `branch_clear`)."""

    def clear(q: np.ndarray) -> np.ndarray:
        reach = placed.clearance_mm + 50.0
        return link_clearance_mm(robot, q, placed.obstacles, reach) >= placed.clearance_mm

    return clear
