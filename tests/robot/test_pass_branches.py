"""The order a pass's IK branches are taken in, their links checked lazily (`by_flown`)."""

from __future__ import annotations

import numpy as np

from scanplan.robot.pass_branches import by_flown, flown_count


class _Cell:
    """Links clear along branch k up to pose `clear_until[k]`; counts the branches asked."""

    def __init__(self, clear_until: list[int]) -> None:
        self.clear_until, self.asked = clear_until, []

    def clear_along(self, i: int, path: np.ndarray) -> np.ndarray:
        assert path.shape[1] == 1
        k = int(np.nanmax(path[:, 0, 0]))  # the branch's joints carry its index
        self.asked.append(k)
        return (np.arange(len(path)) < self.clear_until[k])[:, None]

    def clear_move(self, i0, q0, i1, q1) -> bool:
        return True


def _pass(m: int, reach: list[int]) -> tuple[np.ndarray, np.ndarray]:
    held = np.stack([np.arange(m) < r for r in reach], axis=1)
    path = np.broadcast_to(np.arange(len(reach), dtype=float)[None, :, None], (m, len(reach), 6))
    return held, np.array(path)


def test_the_order_is_most_flown_with_the_links_then_nearest_then_branch() -> None:
    held, path = _pass(10, [10, 10, 6, 10])  # without the links
    cell = _Cell([4, 10, 10, 10])  # branch 0's links meet the cell at pose 4
    dist = np.array([0.0, 3.0, 0.0, 1.0])
    order = list(by_flown(held, path, dist, cell, 0))
    exact = np.minimum(flown_count(held), cell.clear_until)
    expected = np.lexsort((dist, -exact))
    assert [k for k, _ in order] == expected.tolist() == [3, 1, 2, 0]
    assert [n for _, n in order] == exact[expected].tolist()


def test_only_the_branches_the_choice_reaches_have_their_links_checked() -> None:
    held, path = _pass(10, [10, 10, 6, 3])
    cell = _Cell([10, 10, 10, 10])
    order = by_flown(held, path, np.array([2.0, 1.0, 0.0, 0.0]), cell, 0)
    assert next(order) == (1, 10)  # the nearest of the two that fly the whole pass
    assert cell.asked == [1]  # the other full branch waits until it is asked for
    assert next(order) == (0, 10)
    assert cell.asked == [1, 0]
