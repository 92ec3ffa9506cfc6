"""The coverage accumulator marks exactly the samples its definition names: those within the
radius of a point, on the sample's side (the brute-force answer)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from scanplan.core.quantities import ScanSpec
from scanplan.judging.accumulators import SAME_SIDE_COS, Coverage
from scanplan.world.surface import VisibleSurface


def _sheet(rng: np.random.Generator, n: int, thickness: float):
    """Samples on both faces of a thin sheet, with their outward normals."""
    xy = rng.uniform(0, 40, (2 * n, 2))
    z = np.r_[np.zeros(n), np.full(n, -thickness)]
    normals = np.zeros((2 * n, 3))
    normals[:n, 2], normals[n:, 2] = 1.0, -1.0
    return np.column_stack([xy, z]), normals


@pytest.mark.parametrize("with_normals", [False, True])
def test_marks_the_samples_within_the_radius_on_their_side(with_normals):
    rng = np.random.default_rng(7)
    samples, sample_normals = _sheet(rng, 3000, 0.3)
    surface = VisibleSurface(samples, 1600.0, np.zeros(len(samples), np.int64))
    radius = 1.2
    coverage = Coverage(surface, ScanSpec(), 1, radius, radius, sample_normals)
    # Points over both faces, most of them under the sheet: the nearest point of a top
    # sample is then often on the other side, and a farther one on its own must be found.
    points, point_normals = _sheet(rng, 1500, 0.25)
    points[:, 0] /= 2  # over half the sheet
    points = np.r_[points[1200:], points[:300]]
    point_normals = np.r_[point_normals[1200:], point_normals[:300]]
    marked = np.zeros(len(samples), bool)
    marked[:50] = True  # marked before: stays marked
    coverage._mark(marked, points, point_normals if with_normals else None, radius)

    pairs = cKDTree(samples).query_ball_point(points, radius)
    expected = np.zeros(len(samples), bool)
    expected[:50] = True
    for p, near in enumerate(pairs):
        near = np.asarray(near, np.int64)
        if with_normals:
            near = near[sample_normals[near] @ point_normals[p] >= SAME_SIDE_COS]
        expected[near] = True
    assert marked.sum() > 500 and (~marked).sum() > 500  # neither everything nor nothing
    assert np.array_equal(marked, expected)
