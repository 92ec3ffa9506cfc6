"""Points binned in a uniform grid of cubic cells: which of them lie near a set of other
points, found by the cells those occupy (flags in the grid, no sort), without a tree query
per point. What the coverage of a scan's chunk looks at first: the surface samples near its
points, then tested exactly.
"""

from __future__ import annotations

import numpy as np

# Neighbouring cells, the cell itself included: every point within one cell size of a cell
# lies in one of them.
_NEIGHBOURS = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), -1).reshape(-1, 3)
# At most this many cells: a finer grid of a large part is made coarser (fewer, wider cells).
MAX_CELLS = 8_000_000


class SampleGrid:
    """`points` (k, 3) binned in cells at least `cell_mm` wide (a superset of what `near` is
    asked within: the cell is at least the radius)."""

    def __init__(self, points: np.ndarray, cell_mm: float) -> None:
        points = np.asarray(points, dtype=np.float64)
        self.size = len(points)
        self.lo = points.min(axis=0) if self.size else np.zeros(3)
        extent = points.max(axis=0) - self.lo if self.size else np.zeros(3)
        cell = float(cell_mm)
        # Two empty cells on each side, a point's cell clipped to the inner of them: its
        # neighbours are always in the grid, found by flat offsets with no bounds test.
        while np.prod(np.floor(extent / cell) + 5) > MAX_CELLS:
            cell *= 1.5
        self.cell = cell
        self.shape = (np.floor(extent / cell) + 5).astype(np.int64)
        keys = self._keys(points)
        self.order = np.argsort(keys, kind="stable")
        count = np.bincount(keys, minlength=int(np.prod(self.shape)))
        self.count = count
        self.occupied = count > 0
        self.start = np.cumsum(count) - count  # the cell's first in `order`
        strides = np.array([self.shape[1] * self.shape[2], self.shape[2], 1])
        self._around = _NEIGHBOURS @ strides  # a cell's neighbours' flat offsets

    def _keys(self, points: np.ndarray) -> np.ndarray:
        """The flat index of each point's cell, clipped to the grid's inner border cells
        (which are empty: a point outside reaches only cells next to the border's)."""
        cells = np.floor((points - self.lo) / self.cell) + 2
        np.clip(cells, 1, self.shape - 2, out=cells)
        c = cells.astype(np.int64)
        return (c[:, 0] * self.shape[1] + c[:, 1]) * self.shape[2] + c[:, 2]

    def near(self, points: np.ndarray) -> np.ndarray:
        """Indices of the binned points in the cells of `points` (n, 3), finite, and their
        neighbours: every one within a cell size of one of `points` (and some farther). In
        the grid's cell order, not sorted: neighbours in space come together, so a tree
        asked about them in this order finds them in cache (a quarter faster)."""
        if not self.size or not len(points):
            return np.zeros(0, np.int64)
        flags = np.zeros(len(self.count), bool)
        flags[self._keys(points)] = True
        own = np.flatnonzero(flags)
        flags[(own[:, None] + self._around).ravel()] = True
        flags &= self.occupied
        keys = np.flatnonzero(flags)
        count = self.count[keys]
        total = int(count.sum())
        if total == 0:
            return np.zeros(0, np.int64)
        # The runs order[start : start + count], concatenated without a Python loop.
        first = np.repeat(self.start[keys] - (np.cumsum(count) - count), count)
        return self.order[first + np.arange(total)]
