"""The sample grid finds every binned point within a cell of the points asked about."""

from __future__ import annotations

import numpy as np

from scanplan.world.sample_grid import SampleGrid


def _within(binned: np.ndarray, points: np.ndarray, radius: float) -> np.ndarray:
    d = np.linalg.norm(binned[:, None, :] - points[None, :, :], axis=-1)
    return np.flatnonzero((d <= radius).any(axis=1))


def test_near_holds_every_point_within_a_cell_once_in_cell_order():
    rng = np.random.default_rng(3)
    binned = rng.uniform(-50, 50, (4000, 3)) * [1, 1, 0.1]
    grid = SampleGrid(binned, 5.0)
    for asked in (rng.uniform(-60, 60, (40, 3)), binned[:7] + 4.9):
        near = grid.near(asked)
        assert len(np.unique(near)) == len(near)  # each once
        cells = grid._keys(binned[near])
        assert np.all(np.diff(cells) >= 0)  # neighbours in space together
        assert set(_within(binned, asked, 5.0)) <= set(near)
        assert len(near) < len(binned)  # not everything: the cells rule out the rest


def test_near_outside_the_grid_and_without_points():
    binned = np.random.default_rng(0).uniform(0, 10, (100, 3))
    grid = SampleGrid(binned, 2.0)
    assert len(grid.near(np.array([[1e6, -1e6, 0.0]]))) == 0
    assert len(grid.near(np.zeros((0, 3)))) == 0
    edge = grid.near(np.array([[11.5, 5.0, 5.0]]))  # beyond the edge, within a cell of it
    assert set(_within(binned, np.array([[11.5, 5.0, 5.0]]), 2.0)) <= set(edge)
    assert len(SampleGrid(np.zeros((0, 3)), 2.0).near(binned)) == 0


def test_near_is_exactly_the_points_of_the_neighbouring_cells_even_past_the_border():
    """The samples of the 27 cells around each asked point's cell (clipped into the grid),
    no more: a point past any face of the grid finds only what lies along that face."""
    rng = np.random.default_rng(5)
    binned = rng.uniform(0, 30, (3000, 3))
    grid = SampleGrid(binned, 3.0)
    asked = np.r_[rng.uniform(-40, 70, (60, 3)), [[-50, 15, 15], [15, 80, 15], [31, -1, 31]]]
    shape = tuple(grid.shape)
    own = np.stack(np.unravel_index(grid._keys(asked), shape), -1)
    cells = np.stack(np.unravel_index(grid._keys(binned), shape), -1)
    touching = (np.abs(cells[:, None, :] - own[None]) <= 1).all(axis=-1).any(axis=1)
    assert 0 < touching.sum() < len(binned)
    np.testing.assert_array_equal(np.sort(grid.near(asked)), np.flatnonzero(touching))
