"""The sensor body (a box in the sensor frame) against the part's mesh, the fixtures and the
table, for every pose of a trajectory, scanning or not.

`CollisionChecker` builds a mesh's BVH once; `check` answers per pose with a signed
distance (negative = penetration), after an AABB prefilter that keeps FCL for the poses near
the mesh. `CellChecker` (`checker_for`) takes the least distance over the part, each fixture
and the table plane, and says which of them each pose comes nearest. The FCL shapes are
built in `collision_shapes`; a robot's links, as capsules, are tested in `capsule_collision`.
"""

from __future__ import annotations

import functools
import weakref
from dataclasses import dataclass, field
from typing import Any

import fcl
import numpy as np

from scanplan.core.sensor_spec import SensorSpec
from scanplan.world.cell import Cell
from scanplan.world.collision_shapes import (
    body_corners,
    mesh_object,
    pieces_touch,
    rounded_box,
    triangle_bvh,
)
from scanplan.world.part import Part

# An inside test casts one ray in a direction no axis-aligned edge of a mesh lies along.
_INSIDE_RAY = np.array([0.267, 0.534, 0.802]) / np.linalg.norm([0.267, 0.534, 0.802])
# The most poses after a measured one that may be cleared by it (`CollisionChecker.check`).
_RIDE = 256
# The yes/no test's margin below the clearance (`CollisionChecker.colliding`).
_STRICT_MM = 1e-6


@dataclass(frozen=True)
class CollisionReport:
    """Sensor body vs part, per pose. (n,) arrays.

    distance_mm: signed distance between the body and the part: > 0 apart, < 0 penetrating
        (minus the penetration depth, see `CollisionChecker.check`). Exact where `exact`;
        elsewhere a lower bound that is at least `clearance_mm` (the AABB prefilter or the
        box grown by the clearance proved the pose clear without measuring it).
    exact: (n,) bool, whether FCL measured the distance.
    clearance_mm: the clearance the report was asked for.
    """

    distance_mm: np.ndarray
    exact: np.ndarray
    clearance_mm: float
    # Per obstacle ("part", "table", "fixtures"), the signed distance to it alone.
    by_obstacle: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.distance_mm)

    def colliding_at(self, clearance_mm: float) -> np.ndarray:
        """(n,) bool: closer than `clearance_mm`, or touching (distance <= 0). Only valid for
        clearances up to the report's own."""
        if clearance_mm > self.clearance_mm + 1e-12:
            raise ValueError(
                f"collision report made at {self.clearance_mm:g} mm cannot judge {clearance_mm:g}"
            )
        return (self.distance_mm < clearance_mm) | (self.distance_mm <= 0.0)

    @property
    def colliding(self) -> np.ndarray:
        """(n,) bool: closer to the part than the clearance (or touching it)."""
        return self.colliding_at(self.clearance_mm)

    @property
    def touching(self) -> np.ndarray:
        """(n,) bool: touching or penetrating the part (colliding at 0 mm)."""
        return self.distance_mm <= 0.0

    @property
    def penetration_mm(self) -> np.ndarray:
        """(n,) depth of penetration, 0 where apart."""
        return np.maximum(0.0, -self.distance_mm)

    @property
    def worst_penetration_mm(self) -> float:
        return float(self.penetration_mm.max()) if len(self) else 0.0

    def colliding_with(self, obstacle: str) -> np.ndarray:
        """(n,) bool: closer than the clearance to that obstacle (none there: all False)."""
        d = self.by_obstacle.get(obstacle)
        if d is None:
            return np.zeros(len(self), bool)
        return (d < self.clearance_mm) | (d <= 0.0)


class CollisionChecker:
    """The sensor body of `sensor` against `part`, built once per part (the BVH of its mesh).

    The body is `SensorSpec.body_bounds_mm`, a box in the sensor frame; poses are
    `T_part_sensor` (n, 4, 4) in mm.
    """

    def __init__(self, part: Part, sensor: SensorSpec) -> None:
        # No reference to the Part itself: `checker_for` caches checkers weakly by part.
        self.part_name = part.name
        self.sensor = sensor
        mesh = part.mesh
        self._ray_engine = part.ray_engine
        self._face_normals = self._ray_engine.face_normals  # (a turned part: turned, not redone)
        self.vertices = np.asarray(mesh.vertices, dtype=np.float64)
        # The BVH is built on the first pose that comes near the part (seconds on a large
        # mesh; a plan whose poses all keep their distance never needs it). Weakly: see above.
        self._part_ref = weakref.ref(part)
        self._faces = np.asarray(mesh.faces)
        self._part_fcl: fcl.CollisionObject | None = None
        self.bounds = np.asarray(part.bounds, dtype=np.float64)
        lo, hi = sensor.body_bounds_mm
        self.body_lo, self.body_hi = lo, hi
        self.body_centre = 0.5 * (lo + hi)
        self.body_half = 0.5 * (hi - lo)
        self._box_obj = fcl.CollisionObject(fcl.Box(*(hi - lo)), fcl.Transform())
        self._point_obj = fcl.CollisionObject(fcl.Sphere(1e-9), fcl.Transform())
        self._grown: dict[float, fcl.CollisionObject] = {}
        self._rounded_by: dict[float, list[tuple[fcl.CollisionObject, np.ndarray, np.ndarray]]] = {}
        # A box inside a closed mesh touches no triangle: FCL calls it apart. Only a closed
        # mesh has an inside to test; asked on the first body near the part (0.3 s on the
        # door's mesh, cached on the original's).
        self._closed_mesh = mesh if part.turned_from is None else part.turned_from[0].mesh
        self._vertex_tree: Any = None  # a cKDTree of the vertices, built on first need

    @functools.cached_property
    def _closed(self) -> bool:
        return bool(self._closed_mesh.is_watertight)

    @property
    def body_radius_mm(self) -> float:
        """The farthest the body reaches from the sensor origin (for rotation sampling)."""
        return float(np.linalg.norm(body_corners(self.sensor), axis=1).max())

    def body_corners_part(self, poses: np.ndarray) -> np.ndarray:
        """(n, 8, 3) the body's corners in the part frame."""
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        corners = body_corners(self.sensor)
        return np.einsum("nij,kj->nki", poses[:, :3, :3], corners) + poses[:, None, :3, 3]

    def aabb_gap_mm(self, poses: np.ndarray) -> np.ndarray:
        """(n,) distance between the body's part-frame AABB and the part's AABB (0 if they
        overlap): a lower bound on the body-part distance."""
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        rot = poses[:, :3, :3]
        centre = rot @ self.body_centre + poses[:, :3, 3]
        half = np.abs(rot) @ self.body_half
        lo, hi = self.bounds
        gap = np.maximum(lo - (centre + half), (centre - half) - hi)
        return np.linalg.norm(np.maximum(gap, 0.0), axis=1)

    def check(
        self,
        poses: np.ndarray,
        clearance_mm: float,
        exact: bool = False,
    ) -> CollisionReport:
        """Body vs part for every pose (n, 4, 4).

        Stages: poses whose body AABB is at least the clearance from the part's AABB are
        clear without FCL; the rest collide with the body grown by the clearance (a box that
        holds every point within the clearance of the body), and those touching it are
        taken in order: a pose gets an exact `fcl.distance`, and the poses after it whose body
        corners have moved less than that distance minus the clearance are clear without one
        (no point of a box moves farther than its farthest corner: their distance is at
        least the measured one minus that move; a pass's poses 0.5 mm apart mostly ride on
        one measurement). Penetrating poses get a depth: the deepest a body corner lies
        inside the part or a part vertex inside the body (a lower bound on the translation
        that separates them, exact when a face or a corner presses in), else, for an edge
        crossing an edge, FCL's contact depth. A body wholly inside a closed part counts as
        penetrating by its corners' depth. exact=True: every pose gets `fcl.distance`.
        """
        if not (np.isfinite(clearance_mm) and clearance_mm >= 0):
            raise ValueError(f"clearance must be a finite number >= 0 mm, got {clearance_mm}")
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        n = len(poses)
        gap = self.aabb_gap_mm(poses)
        distance = gap.copy()
        measured = np.zeros(n, bool)
        near = np.flatnonzero(gap <= clearance_mm) if not exact else np.arange(n)
        if clearance_mm > 0 and not exact:
            grown = self._grown_box(clearance_mm)
            request = fcl.CollisionRequest()
            keep = []
            for i in near:
                grown.setTransform(self._transform(poses[i]))
                if fcl.collide(grown, self._part_obj, request, fcl.CollisionResult()):
                    keep.append(i)
                else:  # apart by more than the clearance, unless wholly inside
                    distance[i] = max(gap[i], clearance_mm)
            away = np.setdiff1d(near, keep)
            if self._closed and len(away):
                inside = away[
                    self._inside(poses[away, :3, :3] @ self.body_centre + poses[away, :3, 3])
                ]
                for i in inside:
                    distance[i] = -self._penetration_mm(poses[i])
                    measured[i] = True
            near = np.asarray(keep, dtype=np.int64)
        corners = self.body_corners_part(poses[near]) if len(near) and not exact else None
        at = 0
        while at < len(near):
            i = near[at]
            at += 1
            distance[i] = d = self._distance_mm(poses[i])
            measured[i] = True
            if corners is None or d <= clearance_mm:
                continue
            moved = np.linalg.norm(corners[at : at + _RIDE] - corners[at - 1], axis=2).max(axis=1)
            # Apart by more than the clearance: at least d - moved. Within it: at most
            # max(d, 0) + moved (a point of the body within d of the part moves by at most
            # that), so still within it while that stays below the clearance.
            bound = d - moved if d > clearance_mm else max(d, 0.0) + moved
            sure = bound >= clearance_mm if d > clearance_mm else bound < clearance_mm
            ride = len(sure) if sure.all() else int(np.argmin(sure))
            distance[near[at : at + ride]] = bound[:ride]
            at += ride
        return CollisionReport(distance, measured, float(clearance_mm))

    def colliding(self, poses: np.ndarray, clearance_mm: float) -> np.ndarray:
        """(n,) bool: whether the body at each pose (n, 4, 4) comes closer than `clearance_mm`
        to the part (touches it, at 0) or lies inside a closed one, without
        measuring how far: `check(...).colliding` at `fcl.collide`'s speed. A pose in the
        part meets the first slab of the body grown by the clearance at once, one call; one
        near the part pays for the grown box and the pieces of the rounded box it touches."""
        if not (np.isfinite(clearance_mm) and clearance_mm >= 0):
            raise ValueError(f"clearance must be a finite number >= 0 mm, got {clearance_mm}")
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        out = np.zeros(len(poses), bool)
        near = np.flatnonzero(self.aabb_gap_mm(poses) <= clearance_mm)
        if not len(near):
            return out
        rot = poses[near, :3, :3]
        centre = rot @ self.body_centre + poses[near, :3, 3]
        if clearance_mm > _STRICT_MM:
            # Grown a hair less than the clearance: a body exactly at it is clear, as `check`
            # says (closer than the clearance collides).
            grow = clearance_mm - _STRICT_MM
            pieces, grown = self._rounded(grow), self._grown_box(grow)
        else:
            pieces, grown = [(self._box_obj, np.eye(3), np.zeros(3))], None
        out[near] = pieces_touch(pieces, grown, self._part_obj, rot, centre)
        if self._closed:  # a body wholly inside a closed part touches no triangle
            apart = np.flatnonzero(~out[near])
            out[near[apart]] = self._inside(centre[apart])
        return out

    def _distance_mm(self, pose: np.ndarray) -> float:
        """The exact signed distance of the body at `pose` (negative: penetration depth)."""
        self._box_obj.setTransform(self._transform(pose))
        d = fcl.distance(self._box_obj, self._part_obj, fcl.DistanceRequest(), fcl.DistanceResult())
        # A body apart from every triangle may still be inside a closed part.
        if d <= 0 or (
            self._closed and self._inside((pose[:3, :3] @ self.body_centre + pose[:3, 3])[None])[0]
        ):
            return -self._penetration_mm(pose)
        return float(d)

    def _rounded(
        self, clearance_mm: float
    ) -> list[tuple[fcl.CollisionObject, np.ndarray, np.ndarray]]:
        """The slabs and capsules of `colliding` (`rounded_box`), each with its rotation and
        offset from the body box's centre in the sensor frame; built once per clearance."""
        pieces = self._rounded_by.get(clearance_mm)
        if pieces is None:
            pieces = self._rounded_by[clearance_mm] = rounded_box(self.body_half, clearance_mm)
        return pieces

    # ---- internals --------------------------------------------------------------------------

    @property
    def _part_obj(self) -> fcl.CollisionObject:
        if self._part_fcl is None:
            part = self._part_ref()
            if part is not None:  # shared with the arm's checks of the same part
                self._part_fcl = mesh_object(part)
            else:  # the checker outlived its part: its own copy
                bvh = triangle_bvh(self.vertices, self._faces)
                self._part_fcl = fcl.CollisionObject(bvh, fcl.Transform())
        return self._part_fcl

    def _grown_box(self, clearance_mm: float) -> fcl.CollisionObject:
        obj = self._grown.get(clearance_mm)
        if obj is None:
            obj = fcl.CollisionObject(
                fcl.Box(*(self.body_hi - self.body_lo + 2 * clearance_mm)), fcl.Transform()
            )
            self._grown[clearance_mm] = obj
        return obj

    def _transform(self, pose: np.ndarray) -> fcl.Transform:
        """The FCL transform of the body box (FCL boxes are centred on their origin)."""
        rot = pose[:3, :3]
        return fcl.Transform(rot, rot @ self.body_centre + pose[:3, 3])

    def _inside(self, points: np.ndarray) -> np.ndarray:
        """(k,) bool: points inside the closed mesh (the first face a ray meets faces away)."""
        directions = np.tile(_INSIDE_RAY, (len(points), 1))
        _, face = self._ray_engine.alone.first_hit(points, directions)  # the part's inside
        hit = face >= 0
        out = np.zeros(len(points), bool)
        out[hit] = self._face_normals[face[hit]] @ _INSIDE_RAY > 0
        return out

    def _surface_distance_mm(self, point: np.ndarray) -> float:
        self._point_obj.setTransform(fcl.Transform(np.eye(3), point))
        return float(
            fcl.distance(
                self._point_obj, self._part_obj, fcl.DistanceRequest(), fcl.DistanceResult()
            )
        )

    def _penetration_mm(self, pose: np.ndarray) -> float:
        depth = 0.0
        if self._closed:  # body corners inside the part: their depth below its surface
            corners = self.body_corners_part(pose)[0]
            for c in corners[self._inside(corners)]:
                depth = max(depth, self._surface_distance_mm(c))
        # Part vertices inside the body: their depth below the body's nearest face.
        if self._vertex_tree is None:
            from scipy.spatial import cKDTree

            self._vertex_tree = cKDTree(self.vertices)
        centre = pose[:3, :3] @ self.body_centre + pose[:3, 3]
        idx = self._vertex_tree.query_ball_point(centre, float(np.linalg.norm(self.body_half)))
        if idx:
            local = (self.vertices[idx] - pose[:3, 3]) @ pose[:3, :3]  # into the sensor frame
            inner = np.minimum(local - self.body_lo, self.body_hi - local).min(axis=1)
            if (inner > 0).any():
                depth = max(depth, float(inner.max()))
        if depth > 0:
            return depth
        # Edges crossing edges: no vertex inside either; FCL's contact depth.
        self._box_obj.setTransform(self._transform(pose))
        result = fcl.CollisionResult()
        request = fcl.CollisionRequest(num_max_contacts=16, enable_contact=True)
        fcl.collide(self._box_obj, self._part_obj, request, result)
        depths = [c.penetration_depth for c in result.contacts]
        return float(min(depths)) if depths else 0.0


_CHECKERS: weakref.WeakKeyDictionary[Part, dict[bytes, CollisionChecker]] = (
    weakref.WeakKeyDictionary()
)


def mesh_checker(part: Part, sensor: SensorSpec) -> CollisionChecker:
    """The checker of this mesh and this sensor body, built once while the part lives (the
    planner and the evaluation of one part share its BVH)."""
    by_body = _CHECKERS.setdefault(part, {})
    key = sensor.body_bounds_mm.tobytes()
    if key not in by_body:
        by_body[key] = CollisionChecker(part, sensor)
    return by_body[key]


class CellChecker:
    """The sensor body against the part, each fixture and the table plane: the least signed
    distance over them, and each one's (`CollisionReport.by_obstacle`)."""

    def __init__(self, part: Part, sensor: SensorSpec, cell: Cell) -> None:
        self.sensor = sensor
        self.part_name = part.name
        self.meshes = [mesh_checker(part, sensor)]
        self.meshes += [mesh_checker(f, sensor) for f in cell.fixtures]
        self.table = cell.table
        # Everything the body must pass above (the transitions' crossing height).
        self.vertices = np.vstack([c.vertices for c in self.meshes])

    @property
    def body_radius_mm(self) -> float:
        return self.meshes[0].body_radius_mm

    def body_corners_part(self, poses: np.ndarray) -> np.ndarray:
        return self.meshes[0].body_corners_part(poses)

    def check(
        self,
        poses: np.ndarray,
        clearance_mm: float,
        exact: bool = False,
    ) -> CollisionReport:
        """`CollisionChecker.check` against every obstacle; the table's distance is exact
        (the lowest body corner's height above the plane)."""
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        reports = [c.check(poses, clearance_mm, exact) for c in self.meshes]
        by_obstacle = {"part": reports[0].distance_mm}
        distance = reports[0].distance_mm.copy()
        measured = reports[0].exact.copy()
        if len(reports) > 1:
            fixtures = np.min([r.distance_mm for r in reports[1:]], axis=0)
            by_obstacle["fixtures"] = fixtures
            closer = fixtures < distance
            distance = np.where(closer, fixtures, distance)
            measured = np.where(closer, np.all([r.exact for r in reports[1:]], axis=0), measured)
        if self.table is not None:
            table = self.table.height_mm(self.body_corners_part(poses)).min(axis=1)
            by_obstacle["table"] = table
            closer = table < distance
            distance = np.where(closer, table, distance)
            measured |= closer
        return CollisionReport(distance, measured, float(clearance_mm), by_obstacle)

    def colliding(self, poses: np.ndarray, clearance_mm: float) -> np.ndarray:
        """(n,) bool: `check(...).colliding` against every obstacle, yes or no
        (`CollisionChecker.colliding`): no distance measured."""
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        out = np.zeros(len(poses), bool)
        if self.table is not None:
            table = self.table.height_mm(self.body_corners_part(poses)).min(axis=1)
            out = (table < clearance_mm) | (table <= 0.0)
        for mesh in self.meshes:
            todo = np.flatnonzero(~out)
            out[todo] = mesh.colliding(poses[todo], clearance_mm)
        return out


def checker_for(part: Part, sensor: SensorSpec, cell: Cell | None = None) -> CellChecker:
    """The checker of this part, its cell (None: nothing around the part) and this sensor
    body; the meshes' BVHs are built once while their parts live."""
    return CellChecker(part, sensor, cell or Cell())
