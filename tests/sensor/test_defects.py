"""Defects injected into a mesh (scanplan.sensor.defects): the surface moves by the defect's depth
at its centre and not at all beyond its reach, is refined to the defect's resolution there, and
placed defects keep their distance."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from scanplan.sensor.defects import Defect, inject, place, shape

Z, X = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])


def _plate() -> trimesh.Trimesh:
    mesh = trimesh.creation.box((400.0, 300.0, 10.0))
    mesh.apply_translation((0, 0, -5.0))  # top face at z = 0
    return mesh


def _top_heights(mesh: trimesh.Trimesh, xy: np.ndarray) -> np.ndarray:
    """The top surface's height at (k, 2) points, by casting down."""
    origins = np.column_stack([xy, np.full(len(xy), 50.0)])
    hits, rays, _ = mesh.ray.intersects_location(origins, np.tile(-Z, (len(xy), 1)))
    z = np.full(len(xy), -np.inf)
    np.maximum.at(z, rays, hits[:, 2])
    return z


@pytest.mark.parametrize(("kind", "sign"), [("dent", -1), ("bump", 1), ("pit", -1)])
def test_radial_defect_depth_and_reach(kind, sign):
    depth, width, _ = shape(kind, 0.2)
    defect = Defect(kind, np.array([30.0, -20.0, 0.0]), Z, X, depth, width)
    mesh, origin = inject(_plate(), [defect])
    assert len(origin) == len(mesh.faces) > 12
    z = _top_heights(mesh, np.array([[30.0, -20.0], [30.0 + 0.55 * width, -20.0], [60.0, 0.0]]))
    assert z[0] == pytest.approx(sign * depth, abs=0.02 * depth)  # the centre, a vertex or near
    assert z[1] == 0.0  # beyond the reach: nominal
    assert z[2] == 0.0
    # Refined to its resolution where it is (edges measured in the plate's plane).
    tri = mesh.vertices[mesh.faces][..., :2]
    near = np.linalg.norm(tri.mean(axis=1) - [30.0, -20.0], axis=1) < width / 2
    edges = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    assert edges[near].max() <= defect.resolution_mm + 1e-9
    # Bottom and sides untouched.
    assert mesh.vertices[:, 2].min() == -10.0


def test_scratch_runs_along_its_direction():
    depth, width, length = shape("scratch", 0.1)
    direction = np.array([0.6, 0.8, 0.0])
    defect = Defect("scratch", np.zeros(3), Z, direction, depth, width, length)
    mesh, _ = inject(_plate(), [defect])
    along = np.outer([0.0, 0.3 * length], direction[:2])
    across = np.array([[-0.8, 0.6]]) * 0.6 * width
    z = _top_heights(mesh, np.vstack([along, across]))
    assert z[0] == pytest.approx(-depth, abs=0.05 * depth)
    assert z[1] == pytest.approx(-depth, abs=0.05 * depth)
    assert z[2] == 0.0  # beyond its half-width


def test_placed_defects_keep_apart():
    rng = np.random.default_rng(3)
    points = np.column_stack([rng.uniform(-150, 150, (5000, 2)), np.zeros(5000)])
    normals = np.tile(Z, (5000, 1))
    placed = place("dent", np.full(12, 0.5), points, normals, np.random.default_rng(0), 20.0)
    assert len(placed) == 12
    centres = np.array([d.centre_mm for d in placed])
    gaps = np.linalg.norm(centres[:, None] - centres[None], axis=2)[np.triu_indices(12, 1)]
    assert gaps.min() >= 20.0 + 2 * placed[0].radius_mm
    with pytest.raises(ValueError, match="unknown defect type"):
        shape("crack", 0.1)
