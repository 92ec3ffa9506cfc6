"""Views and regions (SPEC §3b): segmentation, view frames, candidate views, depth slabs."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from helpers import HEMISPHERE, overhang_part
from scanplan.core.quantities import UP, ScanSpec
from scanplan.judging import SurfaceState, evaluate
from scanplan.planning.pass_path import plan_scan
from scanplan.planning.pipeline import plan_views
from scanplan.planning.view_choice import steep_samples, top_view_may_suffice
from scanplan.planning.views import (
    SCAN_LEVEL,
    SCAN_RULE,
    SCAN_UPHILL,
    VIEW_AXIS_MAX_TILT_DEG,
    View,
    _best_axis,
    _missed_axes,
    _sees,
    candidate_views,
    depth_slabs,
    missed_views,
    plan_view,
    segment_regions,
    view_axis,
)
from scanplan.rl.planners import make_planner
from scanplan.world.cell import Cell
from scanplan.world.collision import checker_for
from scanplan.world.part import Part, part_from_mesh
from scanplan.world.surface import hemisphere_visible_samples

SPEC = ScanSpec()


def test_view_axis_is_the_normal_clamped_to_the_upper_cone():
    assert np.allclose(
        view_axis(np.array([0, 0.5, 1.0])), np.array([0, 0.5, 1]) / math.hypot(0.5, 1)
    )
    clamped = view_axis(np.array([1.0, 0, 0]))
    assert math.degrees(math.acos(clamped[2])) == pytest.approx(VIEW_AXIS_MAX_TILT_DEG)
    assert clamped[0] > 0 and clamped[1] == pytest.approx(0)


def test_view_rotation_maps_its_axis_up_and_back(housing):
    axis = view_axis(np.array([0.3, -0.8, 0.5]))
    view = View.looking_along(axis)
    assert np.allclose(view.R[:3, :3] @ axis, UP)
    part = housing
    rotated = view.part(part)
    assert np.allclose(rotated.mesh.face_normals, part.mesh.face_normals @ view.R[:3, :3].T)
    assert rotated.inspect_faces is not None and rotated.inspect_faces.all()


def test_housing_regions_are_the_top_and_four_walls(housing):
    part = housing
    regions = segment_regions(part)
    tilts = sorted(round(math.degrees(math.acos(r.normal[2]))) for r in regions)
    assert tilts == [0, 60, 60, 60, 60]  # the bottom faces down: not in the surface
    assert sum(r.area_mm2 for r in regions) == pytest.approx(
        hemisphere_visible_samples(part, 2.0).area_mm2, rel=0.02
    )
    assert len(candidate_views(part, SPEC)) == 5


def test_depth_slabs_cut_at_gaps_and_keep_each_within_the_span():
    # Two walls facing +x, 300 mm apart along x: one direction, two depths.
    near = trimesh.creation.box((10.0, 200.0, 100.0))
    far = trimesh.creation.box((10.0, 200.0, 100.0))
    far.apply_translation((-300.0, 0.0, 0.0))
    part = part_from_mesh(trimesh.util.concatenate([near, far]), "walls")
    facing = np.flatnonzero(part.mesh.face_normals[:, 0] > 0.99)
    slabs = depth_slabs(part, facing, np.array([1.0, 0.0, 0.0]), 125.0, 25.0)
    assert len(slabs) == 2
    x = [part.mesh.triangles_center[s, 0] for s in slabs]
    assert {round(float(v.mean())) for v in x} == {5, -295}
    # One deep slab is cut into equal ones no deeper than the span.
    tall = trimesh.creation.box((10.0, 10.0, 400.0)).subdivide().subdivide().subdivide()
    tall_part = part_from_mesh(tall, "post")
    side = np.flatnonzero(np.abs(tall_part.mesh.face_normals[:, 0]) > 0.99)
    cut = depth_slabs(tall_part, side, np.array([0.0, 0.0, 1.0]), 125.0, 1000.0)
    assert len(cut) == 3  # centroids span ~367 mm: three slabs of at most 125
    for s in cut:
        z = tall_part.mesh.triangles_center[s, 2]
        assert z.max() - z.min() <= 125.0
    assert sum(len(s) for s in cut) == len(side)


def test_vertical_walls_get_views_that_see_them_nearly_head_on():
    # A 150 mm tall box: its four vertical sides are a view each, tilted 80° from +Z.
    part = part_from_mesh(trimesh.creation.box((400.0, 300.0, 150.0)), "block")
    axes = [v.axis for v in candidate_views(part, SPEC)]
    tilts = sorted(round(math.degrees(math.acos(a[2]))) for a in axes)
    assert tilts == [0, 80, 80, 80, 80]
    # Held in the air, every wall is scanned whole.
    plans, auto = plan_views(part, SPEC, make_planner("geometric"), "auto", table="none")
    top = evaluate(part, SPEC, plans[0].traj, points_per_profile=256, context=HEMISPHERE)
    both = evaluate(part, SPEC, auto, points_per_profile=256, context=HEMISPHERE)
    # The top view alone holds the lid (a third of the area); the side views the walls.
    assert top.in_spec_coverage < 0.4
    assert both.in_spec_coverage > 0.85


def test_on_a_table_side_views_fly_up_their_walls_and_keep_clear_of_it():
    # The same box on a table at its lowest point: every side view keeps its passes
    # (flown upward, the camera side leading away from the table), and no pose comes
    # within the clearance of the table; the beam held at the view's tilt, not level with
    # the wall, keeps the sensor above the table at the walls' foot too.
    part = part_from_mesh(trimesh.creation.box((400.0, 300.0, 150.0)), "block")
    plans, auto = plan_views(part, SPEC, make_planner("geometric"), "auto")
    assert len(plans) == 5
    for vp in plans[1:]:
        scanning = vp.traj.poses[vp.traj.scanning]
        assert (scanning[:, 2, 1] > 0.9).all()  # y_s, the scan direction, points up
    corners = checker_for(part, SPEC.sensor).body_corners_part(auto.poses)
    assert corners[..., 2].min() >= part.bounds[0, 2] + SPEC.clearance_mm - 1e-6
    m = evaluate(part, SPEC, auto, points_per_profile=256, context=HEMISPHERE)
    assert m.collisions_table == 0 and m.collisions_count == 0
    assert m.in_spec_coverage > 0.95
    # The choice's own estimate: the exact cover by as many views holds at least as much.
    choice = auto.meta["view_choice"]
    assert choice["views_planned"] >= len(plans)
    assert choice["in_spec_exact"] >= choice["in_spec_greedy"] > 0.9


def _box(centre, extents) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=extents)
    box.apply_translation(centre)
    return box


def _two_blocks() -> Part:
    """Two blocks 300 mm apart along x: their +x walls face one way at two depths."""
    return part_from_mesh(
        trimesh.util.concatenate(
            [_box((0, 0, 50), (100, 200, 100)), _box((-300, 0, 50), (100, 200, 100))]
        ),
        "blocks",
    )


def test_missed_views_aim_at_what_is_missed_one_per_depth():
    part = _two_blocks()
    samples = hemisphere_visible_samples(part, 3.0)
    normals = part.mesh.face_normals[samples.faces]
    missed = normals[:, 0] > 0.99
    views = missed_views(part, SPEC, samples, missed, min_samples=50)
    assert len(views) == 2
    for view in views:
        assert math.degrees(math.acos(view.axis[2])) == pytest.approx(VIEW_AXIS_MAX_TILT_DEG)
        assert view.axis[0] > 0.95
        assert view.faces is not None
        assert (part.mesh.face_normals[view.faces, 0] > 0.99).all()
    depths = sorted(float(part.mesh.triangles_center[v.faces, 0].mean()) for v in views)
    assert depths == pytest.approx([-250.0, 50.0])
    # Nothing missed, or too little: no view.
    assert missed_views(part, SPEC, samples, np.zeros_like(missed), 50) == []
    assert missed_views(part, SPEC, samples, missed, int(missed.sum()) + 1) == []


def test_a_missed_slope_in_a_trench_gets_an_axis_steep_enough_to_clear_its_rim():
    # A 70° slope facing a 150 mm wall across a trench: along its normal the wall blocks
    # most beams; tilted back towards +Z they clear it.
    slope = trimesh.creation.box(extents=(200, 200, 10))
    slope.apply_transform(trimesh.transformations.rotation_matrix(math.radians(-70), [0, 1, 0]))
    slope.apply_translation((0, 0, 95))
    wall = _box((-110, 0, 75), (20, 200, 150))
    part = part_from_mesh(trimesh.util.concatenate([slope, wall]), "trench")
    samples = hemisphere_visible_samples(part, 3.0)
    normal = np.array([-math.sin(math.radians(70)), 0, math.cos(math.radians(70))])
    missed = part.mesh.face_normals[samples.faces] @ normal > 0.99
    assert missed.sum() > 100
    views = missed_views(part, SPEC, samples, missed, min_samples=20)
    assert len(views) == 1
    tilt = math.degrees(math.acos(views[0].axis[2]))
    assert 55.0 <= tilt <= 70.0 - 2.0  # turned up from the normal to see past the wall


def test_a_wall_under_an_overhang_is_held_by_a_level_scan_not_one_up_the_tilt():
    # A 40 mm wall 60 mm in under a plate's edge: the beam at the view's tilt clears it,
    # and the camera beside the laser clears it too only at the laser's height (a level
    # scan); scanning up the tilt puts the camera above the beam, the plate in its way.
    part = overhang_part()
    centres = part.mesh.triangles_center
    wall = np.flatnonzero((part.mesh.face_normals[:, 1] < -0.99) & (centres[:, 2] < 0))
    wall_y, wall_top = centres[wall[0], 1], part.mesh.vertices[part.mesh.faces[wall], 2].max()
    axis = view_axis(np.array([0.0, -1.0, 0.0]))
    level = View.looking_along(axis, 1, wall, scan=SCAN_LEVEL)
    along = level.scan_direction()
    assert along is not None and abs(along[2]) < 1e-9  # level in the view frame ...
    assert abs((np.linalg.inv(level.R)[:3, :3] @ along)[2]) < 1e-9  # ... and the part's
    assert View.looking_along(UP).level_direction() is None
    # Up the tilt: a quarter turn from level about the view's axis; the rule: no direction.
    uphill = replace(level, scan=SCAN_UPHILL).scan_direction()
    assert uphill is not None and abs(uphill @ along) < 1e-9 and abs(uphill[2]) < 1e-9
    assert abs((np.linalg.inv(level.R)[:3, :3] @ uphill)[2]) > 0.1  # climbs in the part's
    assert replace(level, scan=SCAN_RULE).scan_direction() is None
    assert View.looking_along(UP, scan=SCAN_UPHILL).scan_direction() is None
    with pytest.raises(ValueError, match="not 'across'"):
        replace(level, scan="across")
    cell = Cell.around(part)
    planner = make_planner("geometric")
    held = {}
    for name, direction in (("level", along), ("up the tilt", uphill)):

        def plan(view_part, view, direction=direction):
            swaths, traj = plan_scan(
                view_part, SPEC, planner, direction=direction, cell=cell.rotated(view.R)
            )
            return len(swaths), traj

        traj = plan_view(part, level, plan).traj
        try:
            m = evaluate(part, SPEC, traj, points_per_profile=128, context=HEMISPHERE)
        except ValueError:  # no valid point: the camera saw none of the part
            held[name] = 0.0
            continue
        assert m.coverage_map is not None
        points = m.coverage_map.points_part
        on_wall = (np.abs(points[:, 1] - wall_y) < 1e-6) & (points[:, 2] < wall_top)
        assert on_wall.sum() > 100
        held[name] = float((m.coverage_map.state[on_wall] == SurfaceState.IN_SPEC).mean())
    assert held["level"] > 0.8, held
    assert held["up the tilt"] < 0.3, held


def test_the_top_view_may_suffice_on_a_plate_not_on_a_tall_box():
    def steep_of(box):
        part = part_from_mesh(trimesh.creation.box(box), "box")
        return steep_samples(part, hemisphere_visible_samples(part, 5.0, 0))

    plate = steep_of((1000.0, 1000.0, 10.0))  # a 1 m plate 10 mm thick: 4 % edges
    assert top_view_may_suffice(plate, 0.93)
    assert not top_view_may_suffice(plate, 0.97)  # too many edges for that target
    assert not top_view_may_suffice(steep_of((200.0, 200.0, 200.0)), 0.93)  # four walls, a top


class _ReachesNearBlock:
    """An arm standing at +x that reaches only samples with x above `x_min`."""

    def __init__(self, x_min: float) -> None:
        self.x_min = x_min
        self.asked = 0

    @property
    def stands_at(self) -> np.ndarray:
        return np.array([900.0, 0.0, 0.0])

    def reaches(self, points: np.ndarray, axis: np.ndarray) -> np.ndarray:
        self.asked += 1
        return points[:, 0] > self.x_min


def test_missed_views_for_an_arm_are_aimed_only_at_what_it_reaches():
    part = _two_blocks()
    samples = hemisphere_visible_samples(part, 3.0)
    missed = part.mesh.face_normals[samples.faces][:, 0] > 0.99
    # It reaches the near block's wall (x = 50), not the far one's (x = -250).
    arm = _ReachesNearBlock(-100.0)
    views = missed_views(part, SPEC, samples, missed, min_samples=50, arm=arm)
    assert arm.asked > 0
    assert len(views) == 1
    assert views[0].faces is not None
    assert part.mesh.triangles_center[views[0].faces, 0].mean() == pytest.approx(50.0)
    # An arm that reaches neither gets no view at all.
    assert missed_views(part, SPEC, samples, missed, 50, arm=_ReachesNearBlock(1e9)) == []


class _ReachesOnlyTiltedTowardsIt:
    """An arm standing at +y that reaches a sample only along an axis tilted towards it."""

    @property
    def stands_at(self) -> np.ndarray:
        return np.array([0.0, 900.0, 0.0])

    def reaches(self, points: np.ndarray, axis: np.ndarray) -> np.ndarray:
        return np.full(len(points), axis[1] > 0.05)


def test_missed_views_for_an_arm_take_the_axis_it_reaches_along_not_the_one_seeing_most():
    # A block's wall is seen as well along its normal (the first axis tried) as tilted
    # towards the arm; the arm reaches only along the tilted one: that one is taken, not
    # the wall given up (as it was when the axis seeing most was taken first).
    part = part_from_mesh(_box((0, 0, 50), (100, 200, 100)), "block")
    samples = hemisphere_visible_samples(part, 3.0)
    missed = part.mesh.face_normals[samples.faces][:, 0] > 0.99
    plain = missed_views(part, SPEC, samples, missed, min_samples=50)
    assert len(plain) == 1 and abs(plain[0].axis[1]) < 0.05  # seen most untilted
    views = missed_views(
        part, SPEC, samples, missed, min_samples=50, arm=_ReachesOnlyTiltedTowardsIt()
    )
    assert len(views) == 1
    assert views[0].axis[1] > 0.05 and views[0].axis[0] > 0.9


class _ReachesByAxis:
    """An arm standing at +y reaching a sample along an axis when the sample lies far
    enough towards it, the farther the more the axis tilts up; counts what it is asked."""

    stands_at = np.array([0.0, 900.0, 0.0])

    def __init__(self) -> None:
        self.asked: list[tuple[float, ...]] = []

    def reaches(self, points: np.ndarray, axis: np.ndarray) -> np.ndarray:
        self.asked.append(tuple(np.round(axis, 9)))
        return points[:, 1] > 400.0 * axis[2] - 100.0 * axis[1] - 60.0


class _ReachesAll(_ReachesByAxis):
    def reaches(self, points: np.ndarray, axis: np.ndarray) -> np.ndarray:
        self.asked.append(tuple(np.round(axis, 9)))
        return np.ones(len(points), bool)


def test_the_axis_an_arm_reaches_most_along_is_found_asking_it_of_fewer_axes():
    # The two blocks' walls: the far one half hidden, more or less by each axis.
    part = _two_blocks()
    samples = hemisphere_visible_samples(part, 3.0)
    normals = part.mesh.face_normals[samples.faces]
    wall = normals[:, 0] > 0.99
    points, normals = samples.points[wall], normals[wall]
    bases = np.array([view_axis(n) for n in np.vstack([normals.mean(axis=0)[None], normals[:8]])])
    arm = _ReachesByAxis()
    axes = _missed_axes(bases, points, arm)
    # Every axis judged, as the choice did before: the first reaching most.
    cos_tol = math.cos(SPEC.tol_angle_rad)
    reached, seeing = [], set()
    for axis in axes:
        sees = _sees(part, points, normals, axis, cos_tol)
        if sees.any():
            seeing.add(tuple(np.round(axis, 9)))
        sees[sees] = _ReachesByAxis().reaches(points[sees], axis)
        reached.append(sees)
    counts = [int(r.sum()) for r in reached]
    first = int(np.argmax(counts))
    assert len(set(counts)) > 1  # the axes differ: the pick could be wrong
    count, axis, which = _best_axis(part, SPEC, points, normals, axes, arm)
    assert count == counts[first]
    np.testing.assert_array_equal(axis, axes[first])
    np.testing.assert_array_equal(which, reached[first])
    # Each axis asked once at most (the samples' normals repeat their mean's: a flat wall).
    assert len(seeing) < len(axes)
    assert len(arm.asked) == len(set(arm.asked)) == len(seeing)
    # An arm reaching all it is asked of: the axes seeing fewer than the first are not asked.
    everywhere = _ReachesAll()
    count, _, _ = _best_axis(part, SPEC, points, normals, axes, everywhere)
    assert count == max(int(_sees(part, points, normals, a, cos_tol).sum()) for a in axes)
    assert len(everywhere.asked) < len(seeing)
