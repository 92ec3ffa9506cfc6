"""Views and regions (SPEC §3b): segmentation, view frames, and the greedy choice of views."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

from scanplan.cli import app
from scanplan.metrics import evaluate, hemisphere_visible_samples, upward_visible_samples
from scanplan.part import part_from_mesh
from scanplan.planners import make_planner, plan_scan
from scanplan.quantities import ScanSpec
from scanplan.trajectory import read_json, read_trajectory, write_json
from scanplan.views import (
    UP,
    VIEW_AXIS_MAX_TILT_DEG,
    View,
    candidate_views,
    plan_views,
    segment_regions,
    view_axis,
)

SPEC = ScanSpec()
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
    top_cov = evaluate(part, SPEC, top, points_per_profile=256, visible="hemisphere")
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
    assert "1 views" in result.stdout
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
