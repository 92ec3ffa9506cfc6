"""Capsules that enclose a robot's links against the part, its fixtures and the table block,
yes or no within a clearance (`CellObstacles`): a point cloud of each mesh's surface clears
the capsules far from it, FCL tests the rest.
"""

from __future__ import annotations

import math

import fcl
import numpy as np

from scanplan.core.sensor_spec import SensorSpec
from scanplan.world.cell import Cell
from scanplan.world.collision import checker_for
from scanplan.world.collision_shapes import mesh_object
from scanplan.world.part import Part


def _z_to(direction: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotations taking +z onto the unit vectors `direction` (n, 3)."""
    d = direction / np.linalg.norm(direction, axis=1, keepdims=True)
    v = np.stack([-d[:, 1], d[:, 0], np.zeros(len(d))], axis=1)  # z x d
    c = d[:, 2]
    vx = np.zeros((len(d), 3, 3))
    vx[:, 0, 1], vx[:, 0, 2], vx[:, 1, 0] = -v[:, 2], v[:, 1], v[:, 2]
    vx[:, 1, 2], vx[:, 2, 0], vx[:, 2, 1] = -v[:, 0], -v[:, 1], v[:, 0]
    flipped = c < -1 + 1e-9  # d = -z: half a turn about x
    k = np.where(flipped, 0.0, 1.0 / np.where(flipped, 1.0, 1.0 + c))
    R = np.eye(3) + vx + (vx @ vx) * k[:, None, None]
    R[flipped] = np.diag([1.0, -1.0, -1.0])
    return R


def _surface_points(mesh, spacing_mm: float) -> np.ndarray:
    """(k, 3) points on the mesh, every surface point within 2·`spacing_mm` of one: its
    vertices, and on each larger triangle a grid along its two edges from an end of its
    shortest edge, at most `spacing_mm` apart along each (a sliver gets a row of points, not
    a square grid of its longest edge)."""
    tri = np.asarray(mesh.triangles, dtype=np.float64)
    edge = np.linalg.norm(tri[:, [1, 2, 0]] - tri, axis=2)  # edge k runs from vertex k
    start = edge.argmin(axis=1)  # the shortest edge's first vertex
    order = (start[:, None] + np.arange(3)) % 3
    tri = np.take_along_axis(tri, order[:, :, None], axis=1)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    k1 = np.ceil(np.linalg.norm(e1, axis=1) / spacing_mm).astype(np.int64)
    k2 = np.ceil(np.linalg.norm(e2, axis=1) / spacing_mm).astype(np.int64)
    points = [np.asarray(mesh.vertices, dtype=np.float64)]
    big = np.flatnonzero((k1 > 1) | (k2 > 1))
    if not len(big):  # a fine mesh: its vertices are close enough
        return points[0]
    # The larger triangles grouped by their grid's shape (one sort, not a mask per shape).
    shapes, group = np.unique(np.column_stack([k1[big], k2[big]]), axis=0, return_inverse=True)
    by_shape = np.split(big[np.argsort(group, kind="stable")], np.cumsum(np.bincount(group))[:-1])
    for (a, b), pick in zip(shapes.tolist(), by_shape, strict=True):
        i, j = np.meshgrid(np.arange(a + 1) / a, np.arange(b + 1) / b, indexing="ij")
        inside = i + j <= 1 + 1e-9
        inside[0, 0] = inside[a, 0] = inside[0, b] = False  # its corners: the vertices above
        u, v = i[inside], j[inside]
        grid = (
            tri[pick, None, 0]
            + u[None, :, None] * e1[pick, None]
            + v[None, :, None] * e2[pick, None]
        )
        points.append(grid.reshape(-1, 3))
    return np.vstack(points)


class _SurfaceProxy:
    """A mesh's surface as points (`_surface_points`, a k-d tree over them): a quick test
    that clears capsules far from the mesh before FCL measures the rest. Every surface point
    lies within `bound_mm` of one, so a capsule whose axis keeps further than its radius plus
    that from every point cannot touch the mesh; one whose axis comes within its radius of a
    point surely does."""

    def __init__(self, part: Part) -> None:
        from scipy.spatial import cKDTree

        extent = float(np.ptp(part.bounds, axis=0).max())
        # The axes are sampled at `pitch`, the surface at half of it: fine enough to clear
        # capsules a few mm away, coarse enough to build in well under a second.
        self.pitch = max(extent / 128.0, 2.0)
        self.bound_mm = self.pitch / 2
        cloud = _surface_points(part.mesh, self.bound_mm / 2)
        # Leaves of 128 points: a surface cloud this dense is searched in a fraction of the
        # nodes (the quadrotor's placement asked 58 000 points near the hull in 1.2 s, not
        # 3.3 s with scipy's 16); the verdicts depend on the distances alone.
        self._tree = cKDTree(cloud, leafsize=128)
        self._lo, self._hi = cloud.min(axis=0), cloud.max(axis=0)
        self._cloud: np.ndarray | None = cloud
        self._field: _DistanceField | None = None  # built when first asked

    def _bounds(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounds (lo, hi) on the distance from each point to the cloud (`_DistanceField`;
        0 and inf outside its grid)."""
        if self._field is None:
            assert self._cloud is not None
            self._field, self._cloud = _DistanceField(self._cloud, self.pitch), None
        return self._field.bounds(points)

    def within(self, segments: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """((m,) maybe, (m,) surely): capsules (m, 2, 3) of radii (m,) that may touch the
        mesh, and those that surely do (a point of the surface lies inside the capsule).
        Points every `pitch` along each axis stand for it (the axis is within pitch / 2 of
        one of them): a capsule surely touches where one of them is within its radius of the
        cloud, and may where one is within its reach (the radius and both bounds). Each
        point's distance is first bounded by the distance field (`_DistanceField`); the
        k-d tree's exact nearest point is asked only where the bounds straddle the radius
        or the reach, of capsules not yet known to touch."""
        a, b = segments[:, 0], segments[:, 1]
        length = np.linalg.norm(b - a, axis=1)
        count = np.ceil(length / self.pitch).astype(int) + 1
        owner = np.repeat(np.arange(len(segments)), count)
        start = np.r_[0, np.cumsum(count)[:-1]]
        t = (np.arange(count.sum()) - np.repeat(start, count)) / np.repeat(
            np.maximum(count - 1, 1), count
        )
        points = a[owner] + t[:, None] * (b - a)[owner]
        reach = radii + self.bound_mm + 0.5 * self.pitch
        # A point further from the cloud's box than its capsule's reach is further from
        # every point of it (most of an arm's links stand well away from the part).
        box = np.linalg.norm(
            np.maximum(np.maximum(self._lo - points, points - self._hi), 0), axis=1
        )
        asked = np.flatnonzero(box <= reach[owner])
        whose = owner[asked]
        r, rad = reach[whose], radii[whose]
        lo, hi = self._bounds(points[asked])
        maybe, surely = np.zeros(len(segments), bool), np.zeros(len(segments), bool)
        np.logical_or.at(surely, whose, hi <= rad)
        np.logical_or.at(maybe, whose, hi <= r)
        # The bounds straddle the radius or the reach: the exact distance decides (the
        # bounds are within a voxel's diagonal of it, so few points are asked).
        unsure = ((lo <= rad) & (hi > rad)) | ((lo <= r) & (hi > r))
        # A capsule known to touch needs no more; one known to come near, only the radius.
        ask = np.flatnonzero(unsure & ~surely[whose] & ~(maybe[whose] & (lo > rad)))
        if len(ask):
            d, _ = self._tree.query(
                points[asked[ask]], distance_upper_bound=float(r[ask].max()), workers=-1
            )
            np.logical_or.at(surely, whose[ask], d <= rad[ask])
            np.logical_or.at(maybe, whose[ask], d <= r[ask])
        return maybe | surely, surely


class _DistanceField:
    """Bounds on the distance from a point to the nearest point of a cloud, from the
    distance transform (`scipy.ndimage`) of the voxels (`cell` mm) the cloud occupies: the
    distance d between the point's voxel's centre and the nearest occupied voxel's centre
    is within a voxel's diagonal of it (each of the two points lies within half of one of
    its voxel's centre). The grid reaches a margin beyond the cloud; outside it nothing is
    known."""

    def __init__(self, cloud: np.ndarray, cell: float) -> None:
        from scipy.ndimage import distance_transform_edt

        margin = min(32, math.ceil(100.0 / cell))  # voxels: 100 mm, at most 32 of them
        self.cell, self.origin = cell, cloud.min(axis=0) - margin * cell
        self.shape = np.floor((cloud.max(axis=0) - self.origin) / cell).astype(int) + margin + 1
        occupied = np.zeros(self.shape, bool)
        occupied[tuple(self._voxels(cloud).T)] = True
        self.distance = distance_transform_edt(~occupied, sampling=cell)
        self.slack = cell * math.sqrt(3.0) * (1 + 1e-9)

    def _voxels(self, points: np.ndarray) -> np.ndarray:
        return np.floor((points - self.origin) / self.cell).astype(int)

    def bounds(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        voxel = self._voxels(points)
        inside = ((voxel >= 0) & (voxel < self.shape)).all(axis=1)
        d = self.distance[tuple(np.clip(voxel, 0, self.shape - 1).T)]
        return np.where(inside, d - self.slack, 0.0), np.where(inside, d + self.slack, np.inf)


def segment_box_distance(segments: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(m,) the distance (mm) from each segment (m, 2, 3) to the axis-aligned box lo..hi
    (0 where it enters it). The distance from a point moving along a segment to a convex
    set is convex in the segment's parameter: a golden-section search finds its minimum
    (to 1e-9 of the segment's length in 45 steps), for all segments at once."""
    a, d = segments[:, 0], segments[:, 1] - segments[:, 0]

    def dist(t: np.ndarray) -> np.ndarray:
        p = a + t[:, None] * d
        return np.linalg.norm(np.maximum(np.maximum(lo - p, p - hi), 0.0), axis=1)

    g = (np.sqrt(5.0) - 1.0) / 2.0
    left, right = np.zeros(len(a)), np.ones(len(a))
    x1, x2 = right - g * (right - left), left + g * (right - left)
    f1, f2 = dist(x1), dist(x2)
    for _ in range(45):
        lower = f1 <= f2  # the minimum lies in [left, x2], else in [x1, right]
        left, right = np.where(lower, left, x1), np.where(lower, x2, right)
        new = np.where(lower, right - g * (right - left), left + g * (right - left))
        value = dist(new)
        x1, f1, x2, f2 = (
            np.where(lower, new, x2),
            np.where(lower, value, f2),
            np.where(lower, x1, new),
            np.where(lower, f1, value),
        )
    return np.minimum.reduce([f1, f2, dist(np.zeros(len(a))), dist(np.ones(len(a)))])


class CellObstacles:
    """The part, its fixtures and the table block (`Cell.table_block`) in part coordinates,
    for capsules that enclose a robot's links: `capsules_hit` says which obstacle, if any,
    comes within a clearance of each capsule; and, given the sensor, whether its body keeps
    its clearance at poses other than those planned (`sensor_clear`)."""

    NAMES = ("part", "fixture", "table")

    def __init__(
        self,
        part: Part,
        cell: Cell,
        clearance_mm: float,
        sensor: SensorSpec | None = None,
    ) -> None:
        # What every link and the sensor body keep from the part, a fixture and the table.
        self.clearance_mm = float(clearance_mm)
        # The sensor body, for poses the arm would fly otherwise than planned (turned).
        self._sensor = None if sensor is None else checker_for(part, sensor, cell)
        self._objects: list[tuple[int, fcl.CollisionObject, np.ndarray, _SurfaceProxy | None]] = [
            (0, mesh_object(part), np.asarray(part.bounds, np.float64), _SurfaceProxy(part))
        ]
        for fixture in cell.fixtures:
            self._objects.append(
                (
                    1,
                    mesh_object(fixture),
                    np.asarray(fixture.bounds, np.float64),
                    _SurfaceProxy(fixture),
                )
            )
        block = cell.table_block(part)
        if block is not None:
            lo, hi = block
            box = fcl.CollisionObject(fcl.Box(*(hi - lo)), fcl.Transform(0.5 * (lo + hi)))
            self._objects.append((2, box, np.array([lo, hi]), None))
        if (disk := cell.disk) is not None:  # a turntable's disk and body, axis along z
            top = np.asarray(disk.top_mm, dtype=np.float64)
            centre = top - [0.0, 0.0, disk.height_mm / 2]
            cylinder = fcl.Cylinder(disk.radius_mm, disk.height_mm)
            reach = np.array([disk.radius_mm, disk.radius_mm, disk.height_mm / 2])
            self._objects.append(
                (
                    2,
                    fcl.CollisionObject(cylinder, fcl.Transform(centre)),
                    np.array([centre - reach, centre + reach]),
                    None,
                )
            )
        self.table_block = block
        self.part_bounds = np.asarray(part.bounds, dtype=np.float64)  # where no arm stands

    def sensor_clear(self, poses: np.ndarray, clearance_mm: float | None = None) -> np.ndarray:
        """(n,) bool: the sensor body at poses (n, 4, 4) keeps `clearance_mm` (None: its
        clearance) from the part, the fixtures and the table (all True when no sensor was
        given)."""
        if self._sensor is None:
            return np.ones(len(poses), bool)
        clearance = self.clearance_mm if clearance_mm is None else clearance_mm
        return ~self._sensor.colliding(poses, clearance)

    def capsules_hit(
        self, ends: np.ndarray, radii: np.ndarray, clearance_mm: float, exact: bool = True
    ) -> np.ndarray:
        """(n, k) int: for capsules (n, k, 2, 3) (segment ends in part coordinates, mm) of
        radii (k,) or (n, k), the index into NAMES of an obstacle within `clearance_mm` of
        the capsule, -1 where none is. An AABB test leaves FCL only the capsules near an
        obstacle. exact=False: a capsule the pre-test cannot clear counts as hitting the
        mesh (a verdict up to a few mm too cautious, without FCL: for ranking placements)."""
        ends = np.asarray(ends, dtype=np.float64)
        n, k = ends.shape[:2]
        grown = np.broadcast_to(np.asarray(radii, dtype=np.float64), (n, k)) + clearance_mm
        hit = np.full((n, k), -1)
        lo = ends.min(axis=2) - grown[..., None]
        hi = ends.max(axis=2) + grown[..., None]
        request = fcl.CollisionRequest()
        for kind, obstacle, (olo, ohi), proxy in self._objects:
            near = (lo <= ohi).all(axis=2) & (hi >= olo).all(axis=2) & (hit < 0)
            rows, links = np.nonzero(near)
            if proxy is not None and len(rows):
                # Sharpened: a capsule sent to FCL cost about 30 ms near the drone, more than
                # the exact query of its points; and without FCL (exact=False) the approximate
                # query alone called links up to twice their clearance away hits.
                maybe, surely = proxy.within(ends[rows, links], grown[rows, links])
                if not exact:
                    surely = maybe
                hit[rows[surely], links[surely]] = kind
                rows, links = rows[maybe & ~surely], links[maybe & ~surely]
            if not len(rows):
                continue
            if proxy is None:  # the table block: an axis-aligned box, its distance exact here
                far = segment_box_distance(ends[rows, links], olo, ohi)
                touch = far <= grown[rows, links]
                hit[rows[touch], links[touch]] = kind
                continue
            seg = ends[rows, links]
            axis = seg[:, 1] - seg[:, 0]
            length = np.linalg.norm(axis, axis=1)
            axis[length < 1e-9] = (0.0, 0.0, 1.0)  # a sphere: any axis will do
            rot = _z_to(axis)
            mid = 0.5 * (seg[:, 0] + seg[:, 1])
            for i, j, R, c, h in zip(rows, links, rot, mid, length, strict=True):
                shape = fcl.Capsule(float(grown[i, j]), float(max(h, 1e-6)))
                capsule = fcl.CollisionObject(shape, fcl.Transform(R, c))
                if fcl.collide(capsule, obstacle, request, fcl.CollisionResult()):
                    hit[i, j] = kind
        return hit
