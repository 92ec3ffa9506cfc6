"""The surface to inspect (surface.py): what the upper hemisphere sees beyond a top-down
raster, and the share of it any beam within tolerance reaches (the visibility ceiling)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from helpers import fixture_files, sloped_housing
from scanplan.world.part import part_from_mesh
from scanplan.world.surface import (
    hemisphere_visible_samples,
    oriented_normals,
    reachable_samples,
    turned_towards,
    upward_visible_samples,
)


def test_hemisphere_surface_adds_what_only_a_tilted_view_sees(housing):
    # 60° walls are within the top view's 80° slope limit: both surfaces hold them.
    part = housing
    up, hemi = upward_visible_samples(part, 2.0), hemisphere_visible_samples(part, 2.0)
    assert hemi.area_mm2 == pytest.approx(up.area_mm2, rel=0.01)
    # 85° walls: only the hemisphere's tilted directions see them.
    steep = sloped_housing(slope_deg=85.0)
    up, hemi = upward_visible_samples(steep, 2.0), hemisphere_visible_samples(steep, 2.0)
    walls = 2 * (600 + 400) * 150 / math.sin(math.radians(85.0))
    assert hemi.area_mm2 == pytest.approx(up.area_mm2 + walls, rel=0.03)


def _shelf_over_plate():
    """A 400 x 400 plate (top at z = 0) under a 200 x 200 shelf 60 mm above it: the plate
    under the shelf is seen only at a slant, from beyond the angle tolerance."""
    plate = trimesh.creation.box((400.0, 400.0, 10.0))
    plate.apply_translation((0, 0, -5.0))
    shelf = trimesh.creation.box((200.0, 200.0, 10.0))
    shelf.apply_translation((0, 0, 65.0))
    return part_from_mesh(trimesh.util.concatenate([plate, shelf]), "shelf")


def test_a_flat_plate_is_all_within_reach(plate):
    tol = math.radians(15.0)
    for surface in (upward_visible_samples(plate, 3.0), hemisphere_visible_samples(plate, 3.0)):
        # Its top from above, its walls by the cone's beam 75° from vertical (within 80°).
        assert reachable_samples(plate, surface, tol).mean() > 0.999


def test_an_overhang_lowers_the_ceiling():
    part = _shelf_over_plate()
    tol = math.radians(15.0)
    surface = hemisphere_visible_samples(part, 3.0)
    reach = reachable_samples(part, surface, tol)
    under = (np.abs(surface.points[:, :2]) < 100.0 - 60.0 * math.tan(tol) - 2.0).all(axis=1) & (
        surface.points[:, 2] < 1.0
    )
    assert under.any() and not reach[under].any()  # 15° from vertical ends on the shelf
    far = (np.abs(surface.points[:, :2]) > 100.0 + 70.0 * math.tan(tol) + 2.0).any(axis=1)
    assert reach[far].all()
    assert 0.5 < reach.mean() < 0.95
    # Its walls (vertical) only within 80° of vertical: a 70° limit leaves them out.
    wall = np.abs(part.ray_engine.face_normals[surface.faces, 2]) < 0.1
    assert reach[wall].mean() > 0.99
    assert not reachable_samples(part, surface, tol, max_tilt_deg=70.0)[wall].any()


def test_a_fixture_lowers_the_ceiling_not_the_surface_to_inspect(plate, tmp_path):
    """A lid 5 mm over 40 % of the plate (x < -60): the surface to inspect is the plate's
    own (its samples and outward normals as without the lid), the beams that reach it stop
    at the lid, all but those within 5·tan 15° = 1.3 mm of its open edges."""
    lid = trimesh.load(fixture_files(tmp_path, plate)[0])
    lidded = plate.among([lid])
    tol = math.radians(15.0)
    for sampler in (upward_visible_samples, hemisphere_visible_samples):
        alone, among = sampler(plate, 3.0), sampler(lidded, 3.0)
        assert np.array_equal(alone.points, among.points) and alone.area_mm2 == among.area_mm2
        x, on_top = among.points[:, 0], among.points[:, 2] > -1e-6
        reach = reachable_samples(lidded, among, tol)
        hidden = on_top & (x > -298.0) & (x < -62.0)
        assert hidden.sum() > 0.35 * on_top.sum() and not reach[hidden].any()
        assert reach[on_top & (x > -60.0)].all()
        assert reachable_samples(plate, among, tol).all()
    # A sheet (not closed) under a lid still faces up: the lid turns no normal.
    sheet = trimesh.Trimesh([[-200, -150, 0], [200, -150, 0], [200, 150, 0], [-200, 150, 0]],
                            [[0, 1, 2], [0, 2, 3]])  # fmt: skip
    alone = part_from_mesh(sheet, "sheet")
    lid = trimesh.creation.box((500.0, 400.0, 10.0))
    lid.apply_translation((0, 0, 10.0))
    assert np.array_equal(oriented_normals(alone.among([lid])), oriented_normals(alone))
    assert (oriented_normals(alone)[:, 2] > 0.99).all()


def test_the_ceiling_is_found_once_per_part_and_samples():
    """Asked again of the same part and samples, the reachable samples are those found the
    first time (read-only); another tolerance, seed or part finds them anew."""
    part = _shelf_over_plate()
    surface = hemisphere_visible_samples(part, 3.0)
    tol = math.radians(15.0)
    first = reachable_samples(part, surface, tol)
    assert reachable_samples(part, surface, tol) is first and not first.flags.writeable
    wider = reachable_samples(part, surface, math.radians(30.0))
    assert wider is not first and wider.sum() > first.sum()  # a wider cone reaches more
    other = reachable_samples(part, surface, tol, seed=1)
    assert other is not first
    again = reachable_samples(_shelf_over_plate(), surface, tol)  # another part, same mesh
    assert again is not first and np.array_equal(again, first)


def test_a_direction_is_turned_towards_another_by_at_most_the_angle():
    n = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.6, 0.8], [0.0, 0.28, 0.96]])
    to = np.array([0.0, 0.0, 1.0])
    out = turned_towards(n, to, np.radians(30.0))
    assert np.allclose(np.linalg.norm(out, axis=1), 1.0)
    angle_to = np.degrees(np.arccos(np.clip(out @ to, -1, 1)))
    # 90° and 36.9° away: turned by 30°; 16.3° away: nearer than that, so `to` itself.
    assert angle_to[:3] == pytest.approx([60.0, 60.0, 36.87 - 30.0], abs=0.01)
    assert np.allclose(out[3], to)
    # Turned in the plane of n and `to`: the first stays in the x-z plane.
    assert out[0, 1] == pytest.approx(0.0)
