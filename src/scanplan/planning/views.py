"""Views and regions, geometry only: the surface to inspect cut into regions by normal
direction, and a view (a top-view raster of the part rotated so the view's up is +Z) per
region. `view_choice` chooses among them and `view_joining` joins the chosen.

A view is planned with the top-view machinery unchanged: the part is rotated by the view's
R (the view's up axis to +Z), restricted to the region's faces as a region of interest, and
planned as a top view; the poses come back as R⁻¹ @ T.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial.transform import Rotation

from scanplan.core.quantities import UP, ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.world.part import Part
from scanplan.world.surface import (
    VIEW_AXIS_MAX_TILT_DEG,
    VisibleSurface,
    hemisphere_directions,
    oriented_normals,
    towards_up,
    turned_towards,
)

# A region (and a view's slab) smaller than this share of the surface gets no view of its
# own: it still counts in coverage, but a view for it would add nothing measurable.
MIN_REGION_AREA_FRACTION = 0.005


@dataclass(frozen=True)
class Region:
    """A connected patch of the surface to inspect whose normals share a direction bin.

    faces: (k,) int face indices; normal: (3,) its area-weighted mean normal (unit);
    area_mm2: its area.
    """

    faces: np.ndarray
    normal: np.ndarray
    area_mm2: float


def segment_regions(
    part: Part,
    directions: np.ndarray | None = None,
    min_area_fraction: float = MIN_REGION_AREA_FRACTION,
    max_normal_tilt_rad: float = math.pi / 2,
) -> list[Region]:
    """The surface to inspect (the part's region of interest, else every face whose normal
    leans at most `max_normal_tilt_rad` from +Z: the upper hemisphere by default; a wall
    with a draft leaning a few degrees down is still in reach of a tilted beam) cut into
    regions: each face goes to the nearest of `directions` by its
    (oriented) normal, and the connected components of same-direction faces over the mesh's
    face adjacency are the regions. Regions below `min_area_fraction` of the surface are
    dropped (they still count in coverage; a view for each would add nothing measurable).
    Largest first."""
    dirs = hemisphere_directions() if directions is None else directions
    normals = oriented_normals(part)
    mesh = part.mesh
    area = np.asarray(mesh.area_faces)
    inspect = part.inspect_mask & (normals[:, 2] > math.cos(max_normal_tilt_rad) - 1e-6)
    label = np.argmax(normals @ dirs.T, axis=1)
    adj = np.asarray(mesh.face_adjacency)
    same = inspect[adj[:, 0]] & inspect[adj[:, 1]] & (label[adj[:, 0]] == label[adj[:, 1]])
    a, b = adj[same, 0], adj[same, 1]
    f = len(mesh.faces)
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(f, f))
    _, comp = connected_components(graph, directed=False)
    comp = np.where(inspect, comp, -1)
    total = float(area[inspect].sum())
    regions = []
    ids, inverse = np.unique(comp[inspect], return_inverse=True)
    face_ids = np.flatnonzero(inspect)
    comp_area = np.bincount(inverse, area[inspect])
    for k in np.flatnonzero(comp_area >= min_area_fraction * total):
        faces = face_ids[inverse == k]
        n = (normals[faces] * area[faces, None]).sum(axis=0)
        regions.append(Region(faces, n / max(np.linalg.norm(n), 1e-12), float(comp_area[k])))
    del ids
    return sorted(regions, key=lambda r: -r.area_mm2)


def view_axis(normal: np.ndarray, max_tilt_deg: float = VIEW_AXIS_MAX_TILT_DEG) -> np.ndarray:
    """The view's up axis (the sensor looks along −axis): the region's mean normal, tilted
    back to at most `max_tilt_deg` from +Z (the sensor above the fixture)."""
    n = np.asarray(normal, dtype=np.float64) / max(float(np.linalg.norm(normal)), 1e-12)
    tilt = math.acos(float(np.clip(n[2], -1.0, 1.0)))
    if tilt <= math.radians(max_tilt_deg):
        return n
    horizontal = np.array([n[0], n[1], 0.0])
    h = np.linalg.norm(horizontal)
    horizontal = horizontal / h if h > 1e-9 else np.array([1.0, 0.0, 0.0])
    t = math.radians(max_tilt_deg)
    return math.sin(t) * horizontal + math.cos(t) * UP


def rotation_to_up(axis: np.ndarray) -> np.ndarray:
    """(4, 4) the smallest rotation taking the unit `axis` to +Z (the view's "up" tilts,
    nothing spins). Not normalized again here: a view read back from a plan file (its
    recorded unit axis) gets the very rotation it was planned with."""
    R = np.eye(4)
    if not np.allclose(axis, UP):
        rot, _ = Rotation.align_vectors([UP], [np.asarray(axis, dtype=np.float64)])
        R[:3, :3] = rot.as_matrix()
    return R


# How a tilted view's passes run (`View.scan`): by the raster's direction rule; level in the
# part frame, across the tilt (`View.level_direction`); or up the tilt, the laser line level.
SCAN_RULE, SCAN_LEVEL, SCAN_UPHILL = "rule", "level", "uphill"


@dataclass(frozen=True)
class View:
    """One raster of the scan, seen along −axis.

    index: order of the view; axis: (3,) unit, the view's up (part frame); R: (4, 4) the
    rotation mapping the part frame to the view frame (axis → +Z); faces: (k,) int the
    faces of its region (None: the whole surface to inspect, the top view); scan: how its
    passes run (`SCAN_RULE`, `SCAN_LEVEL`, `SCAN_UPHILL`; `scan_direction`).
    """

    index: int
    axis: np.ndarray
    R: np.ndarray
    faces: np.ndarray | None = None
    scan: str = SCAN_RULE

    def __post_init__(self) -> None:
        if self.scan not in (SCAN_RULE, SCAN_LEVEL, SCAN_UPHILL):  # else read as up the tilt
            raise ValueError(f"a view is scanned by its rule, level or uphill, not {self.scan!r}")

    @staticmethod
    def looking_along(
        axis: np.ndarray, index: int = 0, faces: np.ndarray | None = None, scan: str = SCAN_RULE
    ) -> View:
        axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
        return View(index, axis, rotation_to_up(axis), faces, scan)

    def part(self, part: Part) -> Part:
        """The part in the view frame (`Part.turned`: its ray engine and collision model
        reused), restricted to the view's region (and the part's ROI). Face order is kept
        (no re-validation), so face masks carry over. The top view of
        the whole surface is the part itself (its ray engine and collision model reused)."""
        if self.faces is None and np.array_equal(self.R, np.eye(4)):
            return part
        mask = part.inspect_mask.copy()
        if self.faces is not None:
            region = np.zeros(len(mask), bool)
            region[self.faces] = True
            mask &= region
        return replace(part.turned(self.R), inspect_faces=mask)

    def key(self) -> tuple[bytes, bytes, str]:
        """What makes two proposed views the same view: their axis, region and scan rule."""
        faces = b"" if self.faces is None else np.sort(np.asarray(self.faces)).tobytes()
        return np.round(self.axis, 9).tobytes(), faces, self.scan

    def level_direction(self) -> np.ndarray | None:
        """The scan direction of a tilted view, in its frame: level in the part frame
        (across the tilt). The camera sits beside the laser along the scan; scanning level
        keeps it at the laser's height, so it sees under an overhang and past a rim the beam
        clears; stepping up the tilt it would look from above or below the beam. None for a
        view looking straight down."""
        across = np.cross(UP, self.axis)
        norm = float(np.linalg.norm(across))
        if norm < 1e-9:
            return None
        return self.R[:3, :3] @ (across / norm)

    def scan_direction(self) -> np.ndarray | None:
        """The scan direction `scan` sets, in the view's frame: level, or up the tilt (a
        quarter turn from level about the view's axis). None: the raster's direction rule
        decides (`SCAN_RULE`, or a view looking straight down, which has no tilt)."""
        level = self.level_direction()
        if level is None or self.scan == SCAN_RULE:
            return None
        return level if self.scan == SCAN_LEVEL else np.cross([0.0, 0.0, 1.0], level)

    def to_part_frame(self, traj: Trajectory) -> Trajectory:
        """A trajectory planned in the view frame, back in the part frame (R⁻¹ @ T)."""
        poses = np.linalg.inv(self.R)[None] @ traj.poses
        return replace(traj, poses=poses)


@dataclass(frozen=True)
class ViewPlan:
    """A view planned: its trajectory (part frame, swath indices from 0) and passes;
    `lean_deg`: its beams raised so for an arm (`view_poses.raised_beams`), and `slide_mm`
    its lines slid so along themselves (`view_poses.slid_lines`); 0: as planned."""

    view: View
    traj: Trajectory
    passes: int
    lean_deg: float = 0.0
    slide_mm: float = 0.0


# The top-view planner: (the part in a view's frame, that view) -> (passes, trajectory).
PlanView = Callable[[Part, "View"], tuple[int, Trajectory]]


def plan_view(part: Part, view: View, plan: PlanView) -> ViewPlan:
    """Plan one view with `plan` on the rotated, region-restricted part; the trajectory
    comes back in the part frame."""
    passes, traj = plan(view.part(part), view)
    return ViewPlan(view, view.to_part_frame(traj), passes)


def depth_slabs(
    part: Part, faces: np.ndarray, axis: np.ndarray, max_span_mm: float, gap_mm: float
) -> list[np.ndarray]:
    """`faces` cut by depth along `axis` (their centroids'): at gaps wider than `gap_mm`, and
    a slab deeper than `max_span_mm` into equal slabs, so each fits one raster's depth
    window (SPEC §3b: a region deeper than the Z range gets passes at the heights it needs;
    one normal direction may also gather walls of several steps far apart)."""
    faces = np.asarray(faces)
    depth = np.asarray(part.mesh.triangles_center)[faces] @ axis
    order = np.argsort(depth)
    sorted_depth = depth[order]
    breaks = np.flatnonzero(np.diff(sorted_depth) > gap_mm) + 1
    slabs = []
    for group in np.split(order, breaks):
        span = float(depth[group].max() - depth[group].min())
        count = max(1, math.ceil(span / max_span_mm - 1e-9))
        if count == 1:
            slabs.append(faces[group])
            continue
        edges = np.linspace(depth[group].min(), depth[group].max(), count + 1)[1:-1]
        which = np.searchsorted(edges, depth[group])
        slabs.extend(faces[group[which == k]] for k in range(count) if (which == k).any())
    return slabs


def candidate_views(
    part: Part,
    spec: ScanSpec,
    max_candidates: int = 32,
    merge_deg: float = 10.0,
    min_area_fraction: float = MIN_REGION_AREA_FRACTION,
) -> list[View]:
    """Views for the largest regions (their axes, `view_axis`); regions whose axes lie within
    `merge_deg` of each other share one view axis, and their faces are cut into depth slabs
    along it (`depth_slabs`: half the Z range at most, a gap of a tenth of it), one view
    per slab of at least `min_area_fraction` of the surface. A wall facing sideways gets a
    view tilted `VIEW_AXIS_MAX_TILT_DEG` from +Z: within 10° of its normal, the sensor
    still above it; a wall leaning up to the angle tolerance the other way (a draft) too."""
    axes: list[np.ndarray] = []
    groups: list[list[np.ndarray]] = []
    # Faces a beam at most VIEW_AXIS_MAX_TILT_DEG from +Z holds within tolerance.
    reach = math.radians(VIEW_AXIS_MAX_TILT_DEG) + spec.tol_angle_rad
    regions = segment_regions(part, min_area_fraction=0.0, max_normal_tilt_rad=reach)
    total = sum(r.area_mm2 for r in regions)
    for region in regions:
        axis = view_axis(region.normal)
        for i, other in enumerate(axes):
            if math.degrees(math.acos(float(np.clip(axis @ other, -1, 1)))) <= merge_deg:
                groups[i].append(region.faces)
                break
        else:
            axes.append(axis)
            groups.append([region.faces])
    area = np.asarray(part.mesh.area_faces)
    z_range = spec.sensor.z_range_mm
    slabs: list[tuple[float, np.ndarray, np.ndarray]] = []
    for axis, group in zip(axes, groups, strict=True):
        for faces in depth_slabs(part, np.concatenate(group), axis, z_range / 2, z_range / 10):
            slab_area = float(area[faces].sum())
            if slab_area >= min_area_fraction * total:
                slabs.append((slab_area, axis, faces))
    slabs.sort(key=lambda t: -t[0])
    return [
        View.looking_along(axis, k + 1, faces)
        for k, (_, axis, faces) in enumerate(slabs[:max_candidates])
    ]


# Tilts back from a missed cluster's mean normal towards +Z tried for its view's axis: a
# wall at the bottom of a pocket is seen only by a beam that leaves it steeply enough to
# clear the pocket's rim, at the cost of part of the angle tolerance.
MISSED_AXIS_TILTS_DEG = (0.0, 5.0, 10.0)
# Axes tried per group of missed samples: its mean normal and this many samples' normals;
# and axes chosen per group, each for what the previous ones do not see.
MISSED_AXIS_SAMPLES = 8
MISSED_AXES_PER_GROUP = 3


def missed_views(
    part: Part,
    spec: ScanSpec,
    surface: VisibleSurface,
    missed: np.ndarray,
    min_samples: int,
    index: int = 1,
    seed: int = 0,
    arm: ArmReach | None = None,
) -> list[View]:
    """Views aimed at what the views chosen so far miss: the `missed` samples of `surface`
    grouped by normal direction (`hemisphere_directions` bins). Within a group, axes are
    chosen one after another, each the one that sees most of the group's samples not yet
    seen (within the angle tolerance of their normal, unobstructed) among
    the group's mean normal and a few of its samples' normals (at most
    `VIEW_AXIS_MAX_TILT_DEG` from +Z, `view_axis`), each also tilted back towards +Z by
    `MISSED_AXIS_TILTS_DEG`; the samples an axis sees are cut into depth slabs along it (a
    gap of the distance tolerance: one raster holds one depth). One view per slab of at
    least `min_samples` samples, its region the faces they lie on. With a placed `arm`
    (`ArmReach`), the axes are also tilted towards where it stands, the axis taken is the one
    the arm reaches most of the samples along (`_best_axis`), and a view is aimed only at the
    samples it reaches there: a group along no axis of which it reaches `min_samples` gets
    none (the arm could fly nothing of it)."""
    idx = np.flatnonzero(missed)
    if len(idx) < min_samples:
        return []
    rng = np.random.default_rng(seed)
    normals = oriented_normals(part)[surface.faces[idx]]
    points = surface.points[idx]
    dirs = hemisphere_directions()
    label = np.argmax(normals @ dirs.T, axis=1)
    views: list[View] = []
    for b in np.unique(label):
        members = np.flatnonzero(label == b)
        for _ in range(MISSED_AXES_PER_GROUP):
            if len(members) < min_samples:
                break
            mean = normals[members].sum(axis=0)
            mean /= max(float(np.linalg.norm(mean)), 1e-12)
            picks = rng.choice(members, min(len(members), MISSED_AXIS_SAMPLES), replace=False)
            bases = np.vstack([mean[None], normals[picks]])
            bases = np.array([view_axis(n) for n in bases])
            axes = _missed_axes(bases, points[members], arm)
            count, axis, sees = _best_axis(part, spec, points[members], normals[members], axes, arm)
            if count < min_samples:
                break
            seen = members[sees]
            members = np.setdiff1d(members, seen)
            depth = points[seen] @ axis
            order = np.argsort(depth)
            breaks = np.flatnonzero(np.diff(depth[order]) > spec.tolerance_mm) + 1
            for group in np.split(order, breaks):
                if len(group) >= min_samples:
                    faces = np.unique(surface.faces[idx[seen[group]]])
                    views.append(View.looking_along(axis, index + len(views), faces))
    return views


class ArmReach(Protocol):
    """A placed arm as `missed_views` aims views for it: `reaches(points, axis)` (k,) bool,
    whether it reaches the sensor looking at each point along -axis; `stands_at` (3,), where
    it stands in the part's frame."""

    def reaches(self, points: np.ndarray, axis: np.ndarray) -> np.ndarray: ...

    @property
    def stands_at(self) -> np.ndarray: ...


def _missed_axes(bases: np.ndarray, points: np.ndarray, arm: ArmReach | None) -> list[np.ndarray]:
    """The axes tried for a group of missed samples (`missed_views`): `bases` tilted towards
    +Z by each of `MISSED_AXIS_TILTS_DEG`, and with an `arm` also towards where it stands
    (level: the arm may stand below the part)."""
    axes = [a for tilt in MISSED_AXIS_TILTS_DEG for a in towards_up(bases, math.radians(tilt))]
    if arm is None:
        return axes
    to_arm = arm.stands_at - points.mean(axis=0)
    to_arm[2] = 0.0
    if np.linalg.norm(to_arm) < 1e-9:
        return axes
    to_arm /= np.linalg.norm(to_arm)
    for tilt in MISSED_AXIS_TILTS_DEG[1:]:
        axes += [view_axis(a) for a in turned_towards(bases, to_arm, math.radians(tilt))]
    return axes


def _best_axis(
    part: Part,
    spec: ScanSpec,
    points: np.ndarray,
    normals: np.ndarray,
    axes: list[np.ndarray],
    arm: ArmReach | None,
) -> tuple[int, np.ndarray, np.ndarray]:
    """(count, axis, which): of `axes`, the first along which most of the samples (`points`,
    `normals`) are seen (`_sees`), and with a placed `arm` reached too: the axis the arm
    reaches most along (a wall's foot may be reached only from a steeper tilt than the one
    seeing most). The arm is asked about the axes seeing most first, and no further once
    an axis sees fewer than the most reached (it could reach no more than it sees)."""
    cos_tol = math.cos(spec.tol_angle_rad)
    # The same axis tried again (the samples' normals on a flat wall are its mean) sees and
    # reaches the same: judged once (the first of equals is taken either way).
    _, once = np.unique(np.round(np.asarray(axes), 9), axis=0, return_index=True)
    axes = [axes[i] for i in np.sort(once)]
    seen = [_sees(part, points, normals, axis, cos_tol) for axis in axes]
    counts = [int(s.sum()) for s in seen]
    if arm is None:
        first = int(np.argmax(counts))
        return counts[first], axes[first], seen[first]
    best: tuple[int, int, np.ndarray] | None = None  # (reached, axis index, which)
    for i in sorted(range(len(axes)), key=lambda i: -counts[i]):  # stable: ties in order
        if best is not None and counts[i] < best[0]:
            break
        reached = seen[i].copy()
        if reached.any():
            reached[reached] = arm.reaches(points[reached], axes[i])
        key = (int(reached.sum()), -i)
        if best is None or key > (best[0], -best[1]):
            best = (key[0], i, reached)
    assert best is not None
    return best[0], axes[best[1]], best[2]


def _sees(
    part: Part, points: np.ndarray, normals: np.ndarray, axis: np.ndarray, cos_tol: float
) -> np.ndarray:
    """(k,) bool: the samples within acos(cos_tol) of facing `axis` whose ray along it
    escapes the part."""
    ok = normals @ axis >= cos_tol
    todo = np.flatnonzero(ok)
    if len(todo):
        start = points[todo] + 0.05 * normals[todo]
        ray = np.broadcast_to(axis, start.shape)
        ok[todo] = ~part.ray_engine.occluded(start, ray, np.full(len(todo), 1e6))
    return ok
