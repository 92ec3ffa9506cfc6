"""The region of interest (roi.py, SPEC §6): parsing and one-line errors, face selection by
box, normal cone and body, and planning and coverage kept to it."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from helpers import BLOCK_BOX, plate_with_block
from scanplan.core.quantities import ScanSpec
from scanplan.judging import evaluate
from scanplan.planning.bands import plan_adaptive_swaths
from scanplan.planning.pass_path import plan_scan
from scanplan.planning.swaths import plan_swaths
from scanplan.rl.planners import make_planner
from scanplan.world.part import part_from_mesh
from scanplan.world.roi import BodyTerm, BoxTerm, ConeTerm, parse_roi
from scanplan.world.surface import upward_visible_samples

SPEC = ScanSpec()


def ramp_part():
    """An 800 x 300 mm part: a flat at z = 50 (x 0..200), a 30° ramp (x 200..400), a flat on
    top (x 400..800)."""
    top = 50.0 + 200.0 * math.tan(math.radians(30))
    xz = np.array(
        [(0, 0), (200, 0), (400, 0), (800, 0), (800, top), (400, top), (200, 50), (0, 50)]
    )
    tris = np.array([(0, 1, 6), (0, 6, 7), (1, 2, 5), (1, 5, 6), (2, 3, 4), (2, 4, 5)])
    mesh = trimesh.creation.extrude_triangulation(xz, tris, 300.0)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, (1, 0, 0)))
    return part_from_mesh(mesh, "ramp")


def test_parse_roi_terms_and_their_and():
    roi = parse_roi("box:1,2,3,-4,5,6; +z:30 ;n:0,0.5,1:20;body:1")
    box, cone, vec, body = roi.terms
    assert box == BoxTerm((-4.0, 2.0, 3.0), (1.0, 5.0, 6.0))
    assert cone == ConeTerm((0.0, 0.0, 1.0), math.radians(30))
    assert np.allclose(vec.axis, np.array([0, 0.5, 1]) / math.hypot(0.5, 1))
    assert body == BodyTerm(1)
    assert parse_roi("-x:45").terms[0] == ConeTerm((-1.0, 0.0, 0.0), math.radians(45))


@pytest.mark.parametrize(
    "text",
    ["", ";", "box:1,2,3", "box:a,b,c,d,e,f", "box:0,0,0,1,1,nan", "foo:1", "+z", "+z:abc",
     "+z:200", "n:0,0,0:30", "n:1,2:30", "body:x", "body:-1"],
)  # fmt: skip
def test_bad_roi_strings_give_one_line_naming_roi(text):
    with pytest.raises(ValueError, match="--roi") as info:
        parse_roi(text)
    assert "\n" not in str(info.value)


def test_empty_selection_names_the_part():
    with pytest.raises(ValueError, match=r"--roi 'body:0;-z:10;\+z:10' selects no surface of ramp"):
        ramp_part().with_roi("body:0;-z:10;+z:10")
    with pytest.raises(ValueError, match="the part has 1 bodies"):
        ramp_part().with_roi("body:1")


def test_block_top_roi_plans_only_the_block_footprint():
    whole = plate_with_block()
    roi = whole.with_roi(BLOCK_BOX + ";+z:10")
    assert roi.mesh is whole.mesh and roi.ray_engine is whole.ray_engine
    top = roi.inspect_vertices
    assert np.allclose(top.min(axis=0), (-150, -100, 60)) and np.allclose(
        top.max(axis=0), (150, 100, 60)
    )
    nominal_whole, nominal_roi = (plan_swaths(p, SPEC.sensor, "x") for p in (whole, roi))
    assert len(nominal_whole) == 3 and len(nominal_roi) == 1
    assert nominal_roi[0].length_mm == pytest.approx(300 + 40)  # the block plus run-in/out
    assert nominal_roi[0].start_mm[2] == pytest.approx(60 + SPEC.working_distance_mm)
    adaptive_whole, adaptive_roi = (plan_adaptive_swaths(p, SPEC, "x") for p in (whole, roi))
    assert len(adaptive_roi) == 1 < len(adaptive_whole)
    assert adaptive_roi[0].length_mm < 0.3 * adaptive_whole[0].length_mm


def test_block_top_roi_coverage_counts_only_the_roi():
    whole = plate_with_block()
    roi = whole.with_roi(BLOCK_BOX + ";+z:10")
    surface = upward_visible_samples(roi, 2.0)
    assert surface.area_mm2 == pytest.approx(300 * 200, rel=0.02)
    assert np.all(np.abs(surface.points[:, 2] - 60) < 1e-6)
    _, traj = plan_scan(roi, SPEC, make_planner("geometric"))
    on_roi = evaluate(roi, SPEC, traj, points_per_profile=256)
    on_whole = evaluate(whole, SPEC, traj, points_per_profile=256)
    assert on_roi.in_spec_coverage > 0.97
    assert on_roi.coverage_fraction > 0.97
    assert on_roi.visible_area_mm2 == pytest.approx(300 * 200, rel=0.02)
    # The same scan over the whole plate covers only a small part of it.
    assert on_whole.in_spec_coverage < 0.2


def test_normal_cone_excludes_the_ramp():
    part = ramp_part()
    flats = part.with_roi("+z:10")
    normals = part.mesh.face_normals[flats.inspect_mask]
    assert np.all(normals[:, 2] > math.cos(math.radians(10)))
    ramp_faces = np.isclose(part.mesh.face_normals[:, 2], math.cos(math.radians(30)))
    assert ramp_faces.any() and not (flats.inspect_mask & ramp_faces).any()
    assert part.with_roi("+z:31").inspect_mask[ramp_faces].all()
    area = upward_visible_samples(flats, 2.0).area_mm2
    assert area == pytest.approx((200 + 400) * 300, rel=0.02)
    ramp_area = 200 / math.cos(math.radians(30)) * 300
    assert upward_visible_samples(part, 2.0).area_mm2 == pytest.approx(area + ramp_area, rel=0.02)


def test_body_selection_follows_split_order():
    a = trimesh.creation.box((100.0, 100.0, 20.0))
    b = trimesh.creation.box((200.0, 50.0, 40.0))
    b.apply_translation((400.0, 0, 0))
    part = part_from_mesh(trimesh.util.concatenate([a, b]), "two")
    bodies = part.mesh.split(only_watertight=False)
    assert len(bodies) == 2
    for i, body in enumerate(bodies):
        sel = part.with_roi(f"body:{i}")
        assert sel.inspect_mask.sum() == len(body.faces)
        assert np.allclose(sel.inspect_vertices.min(axis=0), body.bounds[0])
        assert np.allclose(sel.inspect_vertices.max(axis=0), body.bounds[1])
    with pytest.raises(ValueError, match=r"--roi body:2: the part has 2 bodies \(0..1\)"):
        part.with_roi("body:2")
