"""Built-in procedural parts (parts.build_part): sizes, closed solids, determinism, finely
meshed curved tops, unknown names listed."""

from __future__ import annotations

import numpy as np
import pytest

from scanplan.world.parts import PART_NAMES, build_part, door, drone, training_piece

EXTENTS_MM = {
    "training-piece": (1050.0, 150.0, 50.0),
    "door": (1440.0, 1060.0, 190.0),
    "drone": (350.0, 95.0, 65.0),
}


BUILDERS = {"training-piece": training_piece.build, "door": door.build, "drone": drone.build}


MAX_FACES = {"training-piece": 150_000, "door": 400_000, "drone": 150_000}


def test_part_names():
    assert PART_NAMES == ("training-piece", "door", "drone")


@pytest.mark.parametrize("name", PART_NAMES)
def test_part_is_a_closed_solid_of_the_stated_size(name):
    mesh = build_part(name)
    np.testing.assert_allclose(mesh.extents, EXTENTS_MM[name], rtol=0.02)
    assert mesh.bounds[0, 2] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(mesh.bounds[:, :2].mean(axis=0), 0.0, atol=1e-6)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.body_count == 1
    assert mesh.volume > 0.2 * np.prod(mesh.extents)  # outward normals, solid down to z = 0
    assert len(mesh.faces) < MAX_FACES[name]
    assert len(mesh.nondegenerate_faces()) == len(mesh.faces)


@pytest.mark.parametrize("name", PART_NAMES)
def test_part_is_deterministic_and_returned_as_a_copy(name):
    a = build_part(name)
    a.vertices[:, 2] += 100.0  # must not leak into the cache
    b, c = build_part(name), BUILDERS[name]()  # c bypasses the cache
    assert b is not c
    np.testing.assert_array_equal(b.vertices, c.vertices)
    np.testing.assert_array_equal(b.faces, c.faces)
    assert b.bounds[0, 2] == 0.0


@pytest.mark.parametrize("name", PART_NAMES)
def test_curved_top_is_finely_meshed(name):
    mesh = build_part(name)
    # pairs of upward faces that meet at an angle: the curved zones of the top surface
    up = mesh.face_normals[:, 2] > 0.05
    pairs = mesh.face_adjacency
    bend = up[pairs].all(axis=1) & (np.abs(mesh.face_adjacency_angles) > np.radians(0.5))
    faces = np.unique(pairs[bend])
    tri_xy = mesh.triangles[faces][:, :, :2]  # plan view: the pitch the sensor sweeps over
    longest_mm = np.linalg.norm(tri_xy - np.roll(tri_xy, 1, axis=1), axis=2).max(axis=1)
    assert len(faces) > 1000
    assert np.percentile(longest_mm, 90) < 6.0


def test_unknown_part_names_the_valid_ones():
    with pytest.raises(ValueError, match="unknown part 'bracket'") as info:
        build_part("bracket")
    for name in PART_NAMES:
        assert name in str(info.value)
