"""Which IK branch a scanning pass is flown on, with the arm's links in the cell: the
branches in the order the choice takes them (`reach._pass_start`), each one's links checked
only when the choice gets to it.
"""

from __future__ import annotations

import heapq
from collections.abc import Iterator
from typing import Protocol

import numpy as np


class CellView(Protocol):
    """What the choice of a pass's configuration asks of the cell (`links.LinkClearance`)."""

    def clear_along(self, i: int, path: np.ndarray) -> np.ndarray:
        """(m, b) whether b branches' joints (m, b, 6) from pose i on keep the links clear."""
        ...

    def clear_move(self, i0: int, q0: np.ndarray, i1: int, q1: np.ndarray) -> bool:
        """Whether the joint move from q0 at pose i0 to q1 at pose i1 keeps them clear."""
        ...


def flown_count(held: np.ndarray) -> np.ndarray:
    """(b,) how many poses each branch (a column of `held`, (m, b)) flies from the first."""
    return np.where(held.all(axis=0), len(held), np.argmin(held, axis=0))


def by_flown(
    held: np.ndarray, path: np.ndarray, dist: np.ndarray, cell: CellView, at: int
) -> Iterator[tuple[int, int]]:
    """(branch, poses flown) in the order of most flown with the links in `cell` checked
    along the branch's `path` (m, b, 6), then least `dist`, then branch: each branch's links
    checked only when the branches before it have been taken (flown without them bounds
    flown with them), since checking every branch's links cost a sixth of a plan."""
    upper = flown_count(held)
    heap = [(-int(upper[k]), float(dist[k]), k, False) for k in range(len(dist))]
    heapq.heapify(heap)
    while heap:
        minus, d, k, exact = heapq.heappop(heap)
        if exact:
            yield k, -minus
            continue
        flying = np.cumprod(held[:, k]).astype(bool)
        clear = cell.clear_along(at, np.where(flying[:, None, None], path[:, [k]], np.nan))
        count = int(flown_count((held[:, k] & (clear[:, 0] | ~flying))[:, None])[0])
        heapq.heappush(heap, (-count, d, k, True))


__all__ = ["CellView", "by_flown", "flown_count"]
