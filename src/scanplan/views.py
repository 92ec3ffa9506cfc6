"""Views and regions (SPEC §3b): the surface to inspect cut into regions by normal direction,
a view (a top-view raster of the part rotated so the view's up is +Z) per region, and the
greedy choice of views toward in-spec coverage.

A view is planned with the top-view machinery unchanged: the part is rotated by the view's
R (the view's up axis to +Z), restricted to the region's faces as a region of interest, and
planned with `plan_scan`; the poses come back as R⁻¹ @ T.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial.transform import Rotation

from scanplan.collision import CollisionChecker, checker_for
from scanplan.part import Part
from scanplan.planners import Planner
from scanplan.quantities import COVERAGE_TARGET, OVERLAP, UP, VIEW_CHOICE_FAN_POINTS, ScanSpec
from scanplan.trajectory import Trajectory

VIEW_MODES = ("top", "auto")
# The directions that define what the upper hemisphere sees (the surface `--views auto`
# inspects, `metrics.hemisphere_visible_samples`): +Z and rings up to this tilt.
HEMISPHERE_MAX_TILT_DEG = 75.0
# A view's axis at most this far from +Z: a vertical wall is then seen 10° off its normal,
# inside the 15° tolerance with room for tracking, and the sensor stays above it.
VIEW_AXIS_MAX_TILT_DEG = 80.0
# A region (and a view's slab) smaller than this share of the surface gets no view of its
# own: it still counts in coverage, but a view for it would add nothing measurable.
MIN_REGION_AREA_FRACTION = 0.005


def hemisphere_directions(rings: tuple[tuple[float, int], ...] | None = None) -> np.ndarray:
    """(k, 3) unit directions on the upper hemisphere: +Z and rings (tilt deg, count), each
    ring's azimuths offset by half a step from the previous one. Default 28 directions."""
    rings = rings or ((30.0, 6), (55.0, 9), (HEMISPHERE_MAX_TILT_DEG, 12))
    out = [UP]
    for i, (tilt, count) in enumerate(rings):
        az = (np.arange(count) + 0.5 * (i % 2)) * 2 * math.pi / count
        t = math.radians(tilt)
        out.append(
            np.stack(
                [math.sin(t) * np.cos(az), math.sin(t) * np.sin(az), 0 * az + math.cos(t)], axis=1
            )
        )
    return np.vstack(out)


def oriented_normals(part: Part) -> np.ndarray:
    """(f, 3) face normals pointing out of the part, towards where a sensor could be. A closed,
    consistently wound mesh's own normals; otherwise (real CAD exports) each face's normal
    is turned to the side from which a ray escapes the part (if both, upwards)."""
    mesh = part.mesh
    normals = np.asarray(part.ray_engine.face_normals)
    if mesh.is_watertight and mesh.is_winding_consistent:
        return normals * (1.0 if mesh.volume >= 0 else -1.0)
    centre = np.asarray(mesh.triangles_center)
    far = np.full(len(normals), 1e6)
    eps = 1e-3 * float(np.linalg.norm(part.extents)) + 0.05
    front = ~part.ray_engine.occluded(centre + eps * normals, normals, far)
    back = ~part.ray_engine.occluded(centre - eps * normals, -normals, far)
    flip = (back & ~front) | (back & front & (normals[:, 2] < 0))
    return np.where(flip[:, None], -normals, normals)


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
) -> list[Region]:
    """The surface to inspect (the part's region of interest, else every face that faces the
    upper hemisphere) cut into regions: each face goes to the nearest of `directions` by its
    (oriented) normal, and the connected components of same-direction faces over the mesh's
    face adjacency are the regions. Regions below `min_area_fraction` of the surface are
    dropped (they still count in coverage; a view for each would add nothing measurable).
    Largest first."""
    dirs = hemisphere_directions() if directions is None else directions
    normals = oriented_normals(part)
    mesh = part.mesh
    area = np.asarray(mesh.area_faces)
    inspect = part.inspect_mask & (normals[:, 2] > -1e-6)
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


@dataclass(frozen=True)
class View:
    """One raster of the scan, seen along −axis.

    index: order of the view; axis: (3,) unit, the view's up (part frame); R: (4, 4) the
    rotation mapping the part frame to the view frame (axis → +Z); faces: (k,) int the
    faces of its region (None: the whole surface to inspect, the top view).
    """

    index: int
    axis: np.ndarray
    R: np.ndarray
    faces: np.ndarray | None = None

    @staticmethod
    def looking_along(axis: np.ndarray, index: int = 0, faces: np.ndarray | None = None) -> View:
        axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
        R = np.eye(4)
        if not np.allclose(axis, UP):
            # The smallest rotation taking axis to +Z: the view's "up" tilts, nothing spins.
            rot, _ = Rotation.align_vectors([UP], [axis])
            R[:3, :3] = rot.as_matrix()
        return View(index, axis, R, faces)

    def part(self, part: Part) -> Part:
        """The part in the view frame, restricted to the view's region (and the part's ROI).
        Face order is kept (no re-validation), so face masks carry over. The top view of
        the whole surface is the part itself (its ray engine and collision model reused)."""
        if self.faces is None and np.array_equal(self.R, np.eye(4)):
            return part
        mesh = part.mesh.copy()
        mesh.apply_transform(self.R)
        mask = part.inspect_mask.copy()
        if self.faces is not None:
            region = np.zeros(len(mask), bool)
            region[self.faces] = True
            mask &= region
        return Part(mesh, name=part.name, source=part.source, inspect_faces=mask)

    def to_part_frame(self, traj: Trajectory) -> Trajectory:
        """A trajectory planned in the view frame, back in the part frame (R⁻¹ @ T)."""
        poses = np.linalg.inv(self.R)[None] @ traj.poses
        return replace(traj, poses=poses)


def view_transition(
    checker: CollisionChecker,
    prev_pose: np.ndarray,
    prev_axis: np.ndarray,
    next_pose: np.ndarray,
    next_axis: np.ndarray,
    centre_mm: np.ndarray,
    radius_mm: float,
    clearance_mm: float,
) -> np.ndarray:
    """Non-scanning poses (k, 4, 4) from the last pose of one view to the first of the next,
    ending on it, clear of the part by `clearance_mm` (`motion.plan_transition`: up, across
    above the part, down). Where going straight up from a pose is not clear (a view under an
    overhang), the move first backs out along the view's axis to the sphere of `radius_mm`
    around the part and comes in the same way. Raises ValueError if neither is clear."""
    from scanplan.motion import plan_transition, straight_move

    try:
        moves = plan_transition(checker, prev_pose, next_pose, clearance_mm)
        return np.concatenate([moves, next_pose[None]])
    except ValueError:
        pass

    def backed_out(pose: np.ndarray, axis: np.ndarray) -> np.ndarray:
        out = pose.copy()
        p = pose[:3, 3] - centre_mm
        b = float(p @ axis)
        c = float(p @ p) - radius_mm**2
        out[:3, 3] = pose[:3, 3] + max(0.0, -b + math.sqrt(max(b * b - c, 0.0))) * axis
        return out

    a, b = backed_out(prev_pose, prev_axis), backed_out(next_pose, next_axis)
    moves = np.concatenate(
        [
            straight_move(prev_pose, a[:3, 3]),
            plan_transition(checker, a, b, clearance_mm),
            straight_move(b, next_pose[:3, 3]),
        ]
    )
    report = checker.check(moves, clearance_mm)
    if report.colliding.any():
        where = moves[np.flatnonzero(report.colliding)[0], :3, 3]
        raise ValueError(
            f"no collision-free move between views: the sensor body comes within "
            f"{clearance_mm:g} mm of the part at {np.round(where, 1).tolist()} mm"
        )
    return moves


def order_views(plans: list[ViewPlan]) -> list[ViewPlan]:
    """The views in an order that keeps the moves between them short: the first (the top
    view) stays first, the rest follow a travelling-salesman tour (networkx's threshold
    accepting from a greedy tour, seeded) over the distance from one view's last pose to
    the next one's first (averaged both ways: the tour is symmetric)."""
    if len(plans) <= 2:
        return list(plans)
    import networkx as nx

    first = np.stack([vp.traj.poses[0, :3, 3] for vp in plans])
    last = np.stack([vp.traj.poses[-1, :3, 3] for vp in plans])
    gap = np.linalg.norm(last[:, None] - first[None], axis=-1)
    graph = nx.Graph()
    for i in range(len(plans)):
        for j in range(i + 1, len(plans)):
            graph.add_edge(i, j, weight=0.5 * float(gap[i, j] + gap[j, i]))
    tour = nx.approximation.threshold_accepting_tsp(graph, "greedy", seed=0)[:-1]
    start = tour.index(0)
    order = tour[start:] + tour[:start]
    # Either direction around the tour: the one with the shorter directed moves.
    reverse = [0] + order[1:][::-1]
    cost = [sum(gap[a, b] for a, b in zip(o[:-1], o[1:], strict=True)) for o in (order, reverse)]
    return [plans[i] for i in (order if cost[0] <= cost[1] else reverse)]


@dataclass(frozen=True)
class ViewPlan:
    """A view planned: its trajectory (part frame, swath indices from 0) and passes."""

    view: View
    traj: Trajectory
    passes: int


PlanView = Callable[[Part], tuple[int, Trajectory]]


def plan_view(part: Part, view: View, plan: PlanView) -> ViewPlan:
    """Plan one view with `plan` (the top-view planner: part -> (passes, trajectory)) on the
    rotated, region-restricted part; the trajectory comes back in the part frame."""
    passes, traj = plan(view.part(part))
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
    still above it."""
    axes: list[np.ndarray] = []
    groups: list[list[np.ndarray]] = []
    regions = segment_regions(part, min_area_fraction=0.0)
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


@dataclass(frozen=True)
class ViewSelection:
    """The views chosen and their estimated in-spec coverage after each (`coverage`)."""

    plans: list[ViewPlan]
    coverage: list[float]
    candidates: int


def choose_views(
    part: Part,
    spec: ScanSpec,
    plan: PlanView,
    coverage_target: float = COVERAGE_TARGET,
    min_gain: float = 0.01,
    max_views: int = 16,
    points_per_profile: int = VIEW_CHOICE_FAN_POINTS,
    seed: int = 0,
) -> ViewSelection:
    """Greedy set cover of the surface a sensor can see from the upper hemisphere: the top
    view first (the paper's raster; on a panel it is all there is), then, while in-spec
    coverage is below `coverage_target`, the candidate view (`candidate_views`) that adds
    the most, unless it adds less than `min_gain` (the "useful amount" of SPEC §3b: 1 % of
    the surface). A panel whose top view reaches the target (the door) stays one view.
    Weighing a view's gain against its profiles as well (at least a quarter of the top
    view's in-spec share per profile) was tried and left out: it cost the machined parts
    1-3 points of hemisphere coverage (`benchmarks/compare_views.py`) for views that each
    add more than 1 %.

    Each view's gain is estimated by evaluating its own trajectory alone on the whole part
    with a sub-sampled fan. That is sound because a surface sample's in-spec state depends
    only on the points of one pass (the in-spec test and the density rule look at a point,
    its profile's columns and its neighbouring profiles of the same pass): the in-spec set
    of several views is the union of their in-spec sets on the same (seeded) samples, so the
    set cover is computed exactly on these sets, and a fan of 128 columns finds the same
    samples (the search radius grows with the evaluated column pitch; density is judged on
    the real sensor's columns). Candidates are tried largest possible gain first (their
    region's area not yet in spec) and skipped once that bound is below the best gain found
    (lazy greedy: a view's gain only shrinks as others are chosen)."""
    from scanplan.metrics import SurfaceState, evaluate

    def in_spec_set(vp: ViewPlan) -> np.ndarray:
        m = evaluate(part, spec, vp.traj, seed, points_per_profile, visible="hemisphere")
        assert m.coverage_map is not None
        return m.coverage_map.state == SurfaceState.IN_SPEC

    top = plan_view(part, View.looking_along(UP, 0), plan)
    covered = in_spec_set(top)
    plans, coverage = [top], [float(covered.mean())]
    if coverage[-1] >= coverage_target:
        return ViewSelection(plans, coverage, 0)
    from scanplan.metrics import hemisphere_visible_samples

    candidates = candidate_views(part, spec)
    # The samples on each candidate's faces: the bound on its gain.
    samples = hemisphere_visible_samples(part, _eval_spacing(spec, points_per_profile), seed)
    on_faces = [np.isin(samples.faces, np.asarray(v.faces)) for v in candidates]
    evaluated: dict[int, tuple[ViewPlan, np.ndarray]] = {}
    while len(plans) < max_views and coverage[-1] < coverage_target:
        bounds = [float((m & ~covered).mean()) for m in on_faces]
        best: tuple[float, int] | None = None
        for i in np.argsort(bounds)[::-1]:
            if bounds[i] < min_gain or (best is not None and bounds[i] <= best[0]):
                break
            if i not in evaluated:
                try:
                    vp = plan_view(part, replace(candidates[i], index=len(plans)), plan)
                    evaluated[i] = (vp, in_spec_set(vp))
                except ValueError:  # a view whose passes see nothing of the part
                    on_faces[i] = np.zeros_like(on_faces[i])
                    continue
            gain = float((evaluated[i][1] & ~covered).mean())
            if best is None or gain > best[0]:
                best = (gain, int(i))
        if best is None or best[0] < min_gain:
            break
        vp, cov = evaluated.pop(best[1])
        on_faces[best[1]] = np.zeros_like(on_faces[best[1]])
        plans.append(replace(vp, view=replace(vp.view, index=len(plans))))
        covered |= cov
        coverage.append(float(covered.mean()))
    return ViewSelection(plans, coverage, len(candidates))


def _eval_spacing(spec: ScanSpec, points_per_profile: int) -> float:
    """The sample spacing `metrics.evaluate` uses with that fan (the same samples)."""
    from scanplan.metrics import coverage_spacing_mm

    return coverage_spacing_mm(spec.sensor.with_points(points_per_profile))


def join_views(
    part: Part, plans: list[ViewPlan], spec: ScanSpec
) -> tuple[list[ViewPlan], Trajectory]:
    """One trajectory: each view's swaths renumbered into a block of its own (view k's
    swaths follow view k−1's), joined by `view_transition`s clear of the part by
    `spec.clearance_mm`. `meta["views"]` records, per view, its axis and its swath block
    (first, last), which is how a CSV reader tells the views apart: a view is the block of
    consecutive swaths whose scanning poses look along its axis. A view no clear move
    reaches is left out and counted (`meta["views_unreachable"]`). Returns the views kept,
    renumbered, and the trajectory."""
    checker = checker_for(part, spec.sensor)
    centre = 0.5 * (part.bounds[0] + part.bounds[1])
    # Clear of the part's bounding sphere, and no nearer than the farthest scanning pose.
    reach = max(float(np.linalg.norm(vp.traj.positions_mm - centre, axis=1).max()) for vp in plans)
    radius = max(0.5 * float(np.linalg.norm(part.extents)) + spec.clearance_mm, reach)
    pieces: list[Trajectory] = []
    views: list[dict] = []
    kept: list[ViewPlan] = []
    unreachable = 0
    first = 0
    prev_axis = plans[0].view.axis
    for vp in plans:
        traj = vp.traj
        swath = traj.swath - traj.swath.min() + first
        if pieces:
            try:
                moves = view_transition(
                    checker,
                    pieces[-1].poses[-1],
                    prev_axis,
                    traj.poses[0],
                    vp.view.axis,
                    centre,
                    radius,
                    spec.clearance_mm,
                )[:-1]  # without the next view's first pose, which its trajectory holds
            except ValueError:  # no clear way in: the scan goes on without this view
                unreachable += 1
                continue
            pieces.append(Trajectory(moves, np.full(len(moves), first), np.zeros(len(moves), bool)))
        pieces.append(replace(traj, swath=swath))
        kept.append(replace(vp, view=replace(vp.view, index=len(kept))))
        prev_axis = vp.view.axis
        views.append(
            {
                "index": len(views),
                "axis": [float(c) for c in vp.view.axis],
                "first_swath": int(swath.min()),
                "last_swath": int(swath.max()),
                "passes": vp.passes,
            }
        )
        first = int(swath.max()) + 1
    out = Trajectory.concatenate(pieces)
    meta = dict(out.meta)
    meta["views"] = views
    if unreachable:
        meta["views_unreachable"] = unreachable
    return kept, replace(out, meta=meta)


def default_views(planner: Planner) -> str:
    """`--views` when none is given: auto for a planner that rolls (as `--raster auto`
    adapts its passes), top for the paper's pitch-only planners and a v0 policy, so the
    baselines stay the paper's single raster."""
    return "auto" if planner.roll else "top"


def plan_views(
    part: Part,
    spec: ScanSpec,
    planner: Planner,
    views: str | None = None,
    coverage_target: float = COVERAGE_TARGET,
    raster: str = "auto",
    direction: str = "auto",
    overlap: float = OVERLAP,
) -> tuple[list[ViewPlan], Trajectory]:
    """Plan a scan by views: 'top' the paper's single top raster, 'auto' `choose_views`,
    None the planner's default (`default_views`);
    each view is planned by `planners.plan_scan` (raster, direction, overlap as there) on
    the rotated part. Returns the views and the joined trajectory (`join_views`; its plan
    time: the whole choice)."""
    from scanplan.planners import plan_scan

    views = default_views(planner) if views is None else views
    if views not in VIEW_MODES:
        raise ValueError(f"unknown --views {views!r}; use top or auto")
    if not 0.0 < coverage_target <= 1.0:
        raise ValueError(f"--coverage-target must be in (0, 1], got {coverage_target}")

    def plan(view_part: Part) -> tuple[int, Trajectory]:
        swaths, traj = plan_scan(view_part, spec, planner, raster, direction, overlap)
        return len(swaths), traj

    start = time.perf_counter()
    if views == "top":
        plans = [plan_view(part, View.looking_along(UP, 0), plan)]
    else:
        plans = choose_views(part, spec, plan, coverage_target).plans
    plans, traj = join_views(part, order_views(plans), spec)
    return plans, replace(traj, plan_time_s=time.perf_counter() - start, planner=planner.name)
