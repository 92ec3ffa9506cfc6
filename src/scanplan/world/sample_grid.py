"""Points binned in a uniform grid of cubic cells: which of them lie near a set of other
points, found by the cells those occupy (one sort and a few binary searches), without a
tree query per point. What the coverage of a scan's chunk looks at first: the surface
samples near its points, then tested exactly.
"""

from __future__ import annotations

import numpy as np

# Neighbouring cells, the cell itself included: every point within one cell size of a cell
# lies in one of them.
_NEIGHBOURS = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), -1).reshape(-1, 3)


class SampleGrid:
    """`points` (k, 3) binned in cells `cell_mm` wide (a superset of what `near` is asked
    within: the cell is at least the radius)."""

    def __init__(self, points: np.ndarray, cell_mm: float) -> None:
        self.cell = float(cell_mm)
        points = np.asarray(points, dtype=np.float64)
        self.size = len(points)
        self.lo = points.min(axis=0) if self.size else np.zeros(3)
        cells = self._cells(points).astype(np.int64)
        self.shape = cells.max(axis=0) + 1 if self.size else np.ones(3, np.int64)
        keys = np.ravel_multi_index(tuple(cells.T), tuple(self.shape))
        self.order = np.argsort(keys, kind="stable")
        self.keys = keys[self.order]

    def _cells(self, points: np.ndarray) -> np.ndarray:
        return np.floor((points - self.lo) / self.cell)

    def near(self, points: np.ndarray) -> np.ndarray:
        """Sorted indices of the binned points in the cells of `points` (n, 3), finite, and
        their neighbours: every one within a cell size of one of `points` (and some farther)."""
        if not self.size or not len(points):
            return np.zeros(0, np.int64)
        # A cell outside the grid has no point in it: clipped to one cell beyond its edge,
        # a point far outside still reaches only the edge's cells, which are tested anyway.
        cells = np.clip(self._cells(points), -1, self.shape).astype(np.int64)
        span = self.shape + 3  # cells -1 .. shape, and their neighbours -2 .. shape + 1
        own = np.unique(np.ravel_multi_index(tuple((cells + 2).T), tuple(span)))
        padded = np.stack(np.unravel_index(own, tuple(span)), -1) - 2
        around = (padded[:, None, :] + _NEIGHBOURS).reshape(-1, 3)
        inside = np.all((around >= 0) & (around < self.shape), axis=1)
        keys = np.unique(np.ravel_multi_index(tuple(around[inside].T), tuple(self.shape)))
        left = np.searchsorted(self.keys, keys, side="left")
        count = np.searchsorted(self.keys, keys, side="right") - left
        total = int(count.sum())
        if total == 0:
            return np.zeros(0, np.int64)
        # The runs keys[left : left + count], concatenated without a Python loop.
        first = np.repeat(left - (np.cumsum(count) - count), count)
        return np.sort(self.order[first + np.arange(total)])
