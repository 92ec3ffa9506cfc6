"""Height-field solids (parts.heightfield): closed, of the right volume, bad grids refused."""

from __future__ import annotations

import numpy as np
import pytest

from scanplan.world.parts import heightfield_solid


def test_heightfield_solid_tilted_plate():
    xs, ys = np.linspace(-50, 50, 11), np.linspace(-20, 20, 5)
    z = 30.0 + 0.1 * xs[None, :] + 0.0 * ys[:, None]
    mesh = heightfield_solid(xs, ys, z)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume == pytest.approx(100.0 * 40.0 * 30.0)
    up = mesh.face_normals[mesh.face_normals[:, 2] > 0.05]
    np.testing.assert_allclose(
        up, np.tile([-np.sin(np.arctan(0.1)), 0, np.cos(np.arctan(0.1))], (len(up), 1)), atol=1e-12
    )


def test_heightfield_solid_step_from_a_repeated_x():
    xs, ys = np.array([0.0, 10.0, 10.0, 20.0]), np.array([0.0, 5.0, 10.0])
    z = np.tile([5.0, 5.0, 8.0, 8.0], (3, 1))
    mesh = heightfield_solid(xs, ys, z)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume == pytest.approx(10 * 10 * 5 + 10 * 10 * 8)
    riser = mesh.face_normals[:, 0] < -0.999
    assert mesh.area_faces[riser & (mesh.triangles_center[:, 0] > 1)].sum() == pytest.approx(30.0)


@pytest.mark.parametrize(
    ("xs", "ys", "z", "match"),
    [
        ([0, 1], [0, 1], np.ones((2, 3)), "shape"),
        ([0, 1], [0, 1], np.zeros((2, 2)), "> 0"),
        ([1, 0], [0, 1], np.ones((2, 2)), "non-decreasing"),
        ([0, 1, 1, 1, 2], [0, 1], np.ones((2, 5)), "more than twice"),
    ],
)
def test_heightfield_solid_rejects_bad_input(xs, ys, z, match):
    with pytest.raises(ValueError, match=match):
        heightfield_solid(xs, ys, z)
