"""Views and regions (SPEC §3b): segmentation, view frames, and the greedy choice of views."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

from scanplan.cli import app
from scanplan.collision import checker_for
from scanplan.context import PlanContext
from scanplan.metrics import evaluate
from scanplan.part import part_from_mesh
from scanplan.pipeline import default_views, order_views, plan_scan, plan_views
from scanplan.planners import make_planner
from scanplan.quantities import UP, ScanSpec
from scanplan.surface import hemisphere_visible_samples, upward_visible_samples
from scanplan.trajectory import read_json, read_trajectory, write_json
from scanplan.views import (
    VIEW_AXIS_MAX_TILT_DEG,
    View,
    candidate_views,
    depth_slabs,
    segment_regions,
    view_axis,
)

SPEC = ScanSpec()
HEMISPHERE = PlanContext(SPEC, views="auto")  # judged on what the upper hemisphere sees
SLOPE_DEG = 60.0


def sloped_housing(length=600.0, width=400.0, height=150.0, slope_deg=SLOPE_DEG):
    """A box-shaped housing whose four side walls slope at `slope_deg` from the horizontal."""
    inset = height / math.tan(math.radians(slope_deg))
    lo = [(x, y, 0.0) for x in (-length / 2, length / 2) for y in (-width / 2, width / 2)]
    hi = [
        (x, y, height)
        for x in (-length / 2 + inset, length / 2 - inset)
        for y in (-width / 2 + inset, width / 2 - inset)
    ]
    return part_from_mesh(trimesh.Trimesh(lo + hi).convex_hull, "housing")


def test_view_axis_is_the_normal_clamped_to_the_upper_cone():
    assert np.allclose(
        view_axis(np.array([0, 0.5, 1.0])), np.array([0, 0.5, 1]) / math.hypot(0.5, 1)
    )
    clamped = view_axis(np.array([1.0, 0, 0]))
    assert math.degrees(math.acos(clamped[2])) == pytest.approx(VIEW_AXIS_MAX_TILT_DEG)
    assert clamped[0] > 0 and clamped[1] == pytest.approx(0)


def test_view_rotation_maps_its_axis_up_and_back():
    axis = view_axis(np.array([0.3, -0.8, 0.5]))
    view = View.looking_along(axis)
    assert np.allclose(view.R[:3, :3] @ axis, UP)
    part = sloped_housing()
    rotated = view.part(part)
    assert np.allclose(rotated.mesh.face_normals, part.mesh.face_normals @ view.R[:3, :3].T)
    assert rotated.inspect_faces is not None and rotated.inspect_faces.all()


def test_housing_regions_are_the_top_and_four_walls():
    part = sloped_housing()
    regions = segment_regions(part)
    tilts = sorted(round(math.degrees(math.acos(r.normal[2]))) for r in regions)
    assert tilts == [0, 60, 60, 60, 60]  # the bottom faces down: not in the surface
    assert sum(r.area_mm2 for r in regions) == pytest.approx(
        hemisphere_visible_samples(part, 2.0).area_mm2, rel=0.02
    )
    assert len(candidate_views(part, SPEC)) == 5


def test_hemisphere_surface_adds_what_only_a_tilted_view_sees():
    # 60° walls are within the top view's 80° slope limit: both surfaces hold them.
    part = sloped_housing()
    up, hemi = upward_visible_samples(part, 2.0), hemisphere_visible_samples(part, 2.0)
    assert hemi.area_mm2 == pytest.approx(up.area_mm2, rel=0.01)
    # 85° walls: only the hemisphere's tilted directions see them.
    steep = sloped_housing(slope_deg=85.0)
    up, hemi = upward_visible_samples(steep, 2.0), hemisphere_visible_samples(steep, 2.0)
    walls = 2 * (600 + 400) * 150 / math.sin(math.radians(85.0))
    assert hemi.area_mm2 == pytest.approx(up.area_mm2 + walls, rel=0.03)


def test_housing_auto_views_raise_in_spec_coverage(tmp_path):
    part = sloped_housing()
    planner = make_planner("geometric")
    _, top = plan_scan(part, SPEC, planner)
    plans, auto = plan_views(part, SPEC, planner, "auto")
    assert len(plans) >= 2
    views = auto.meta["views"]
    assert [v["index"] for v in views] == list(range(len(plans)))
    # Swath indices: one consecutive block per view.
    for v in views:
        scan = auto.swath[auto.scanning]
        in_block = (scan >= v["first_swath"]) & (scan <= v["last_swath"])
        assert in_block.any()
    assert views[0]["axis"] == pytest.approx([0, 0, 1])
    top_cov = evaluate(part, SPEC, top, points_per_profile=256, context=HEMISPHERE)
    auto_cov = evaluate(part, SPEC, auto, points_per_profile=256)  # several views: hemisphere
    assert auto_cov.visible_area_mm2 == pytest.approx(top_cov.visible_area_mm2)
    # The top raster rolls its line onto the 60° walls too (0.67), but only views hold them.
    assert auto_cov.in_spec_coverage >= 0.9
    assert auto_cov.in_spec_coverage > top_cov.in_spec_coverage + 0.2
    # Each added view looks along its axis: its scanning poses' beams point against it (the
    # top view's passes roll onto the walls, so its beams tilt).
    for k, v in enumerate(views[1:], start=1):
        scan = auto.scanning & (auto.swath >= v["first_swath"]) & (auto.swath <= v["last_swath"])
        beams = auto.poses[scan][:, :3, 2]
        assert np.median(beams @ np.array(v["axis"])) < -0.8, k
    # The JSON keeps the views' record.
    write_json(auto, tmp_path / "t.json")
    assert read_json(tmp_path / "t.json").meta["views"] == views


def test_views_top_is_the_plain_top_raster():
    part = sloped_housing()
    planner = make_planner("geometric")
    swaths, top = plan_scan(part, SPEC, planner)
    plans, joined = plan_views(part, SPEC, planner, "top")
    assert len(plans) == 1 and plans[0].passes == len(swaths)
    assert np.allclose(joined.poses, top.poses) and (joined.swath == top.swath).all()


def test_bad_views_options_are_one_line(tmp_path):
    out = tmp_path / "t.csv"
    for extra in (["--views", "side"], ["--views", "auto", "--coverage-target", "0"]):
        result = CliRunner().invoke(app, ["plan", "drone", "-o", str(out), *extra])
        assert result.exit_code == 2 and len(result.stderr.strip().splitlines()) == 1
        assert "--views" in result.stderr or "--coverage-target" in result.stderr
        assert not out.exists()


@pytest.mark.slow
def test_door_auto_reduces_to_the_single_top_view(tmp_path):
    out = tmp_path / "door.json"
    result = CliRunner().invoke(app, ["plan", "door", "--views", "auto", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "1 view," in result.stdout
    data = json.loads(out.read_text())
    assert len(data["views"]) == 1 and data["views"][0]["axis"] == pytest.approx([0, 0, 1])
    # The same scan as the plain top raster: same passes, same scanning poses.
    top = tmp_path / "top.csv"
    assert CliRunner().invoke(app, ["plan", "door", "-o", str(top)]).exit_code == 0
    plain, auto = read_trajectory(top), read_trajectory(out)
    assert data["views"][0]["passes"] == len(np.unique(plain.swath))
    np.testing.assert_allclose(
        auto.poses[auto.scanning][:, :3, 3], plain.poses[plain.scanning][:, :3, 3], atol=1e-3
    )


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
    plans, auto = plan_views(part, SPEC, make_planner("geometric"), "auto")
    top = evaluate(part, SPEC, plans[0].traj, points_per_profile=256, context=HEMISPHERE)
    both = evaluate(part, SPEC, auto, points_per_profile=256, context=HEMISPHERE)
    # The top view alone holds the lid (a third of the area); the side views the walls.
    assert top.in_spec_coverage < 0.4
    assert both.in_spec_coverage > 0.85


def test_views_are_ordered_by_a_short_tour_with_the_top_first():
    part = sloped_housing()
    planner = make_planner("geometric")
    plans, auto = plan_views(part, SPEC, planner, "auto")
    assert np.allclose(plans[0].view.axis, UP)

    def moving(order):
        first = [vp.traj.poses[0, :3, 3] for vp in order]
        last = [vp.traj.poses[-1, :3, 3] for vp in order]
        return sum(float(np.linalg.norm(first[k + 1] - last[k])) for k in range(len(order) - 1))

    ordered = order_views(plans)
    assert np.allclose(ordered[0].view.axis, UP)
    assert sorted(id(vp) for vp in ordered) == sorted(id(vp) for vp in plans)
    # No worse than any order a user could have given: every permutation of the rest.
    from itertools import permutations

    best = min(moving([plans[0], *rest]) for rest in permutations(plans[1:]))
    assert moving(ordered) <= best * 1.2


def test_moves_between_views_keep_the_body_clear():
    part = sloped_housing()
    _, auto = plan_views(part, SPEC, make_planner("geometric"), "auto")
    report = checker_for(part, SPEC.sensor).check(auto.poses, SPEC.clearance_mm)
    assert not report.colliding.any()
    # Independently of our checker: python-fcl's own distance for every non-scanning pose.
    from test_collision import fcl_distance

    for pose in auto.poses[~auto.scanning][::2]:
        assert fcl_distance(part, SPEC.sensor, pose) > 0


def test_default_views_follow_whether_the_planner_rolls():
    assert default_views(make_planner("geometric")) == "auto"
    assert default_views(make_planner("feedback")) == "auto"
    assert default_views(make_planner("fixed")) == "top"
    assert default_views(make_planner("geometric", roll=False)) == "top"
    assert default_views(make_planner("rl")) == "top"  # the shipped v0 policy: pitch only


def test_the_door_inspects_its_skin_not_the_solid_sides():
    from scanplan.part import load_part

    door = load_part("door")
    assert door.inspect_faces is not None
    normals = door.mesh.face_normals
    assert (normals[door.inspect_faces, 2] > 0).all()
    sides = np.abs(normals[:, 2]) < 1e-6
    assert sides.any() and not door.inspect_faces[sides].any()
    assert load_part("drone").inspect_faces is None


def test_a_view_no_clear_move_reaches_is_left_out_and_counted(monkeypatch):
    import scanplan.pipeline as pipeline_module

    part = sloped_housing()
    plans, _ = plan_views(part, SPEC, make_planner("geometric"), "auto")
    assert len(plans) >= 3
    real = pipeline_module.view_transition
    calls = {"n": 0}

    def blocked_once(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 1:
            raise ValueError("no collision-free move between views")
        return real(*args, **kwargs)

    monkeypatch.setattr(pipeline_module, "view_transition", blocked_once)
    kept, joined = pipeline_module.join_views(part, plans, SPEC)
    assert joined.meta["views_unreachable"] == 1
    assert len(kept) == len(plans) - 1 and [v.view.index for v in kept] == list(range(len(kept)))
    assert [v["index"] for v in joined.meta["views"]] == list(range(len(kept)))
    assert np.allclose(kept[1].view.axis, plans[2].view.axis)  # the second view was skipped
    assert (
        checker_for(part, SPEC.sensor).check(joined.poses, SPEC.clearance_mm).colliding.sum() == 0
    )


def test_a_straight_move_is_sampled_so_every_place_the_body_passes_is_checked():
    from scanplan.motion import straight_move

    start = np.eye(4)
    start[:3, :3] = View.looking_along(np.array([0.98, 0.0, 0.17])).R[:3, :3].T
    moves = straight_move(start, np.array([0.0, 0.0, 95.0]), step_mm=20.0)
    path = np.vstack([start[:3, 3], moves[:, :3, 3]])
    assert len(moves) == 5 and np.allclose(moves[-1, :3, 3], [0, 0, 95])
    assert np.linalg.norm(np.diff(path, axis=0), axis=1).max() <= 20.0
    assert np.allclose(moves[:, :3, :3], start[:3, :3])  # orientation kept
