"""The exact maximum cover against greedy on a case greedy gets wrong."""

from __future__ import annotations

import numpy as np

from scanplan.core.cover import max_cover


def _sets(n: int, *ranges: tuple[int, int]) -> list[np.ndarray]:
    out = []
    for lo, hi in ranges:
        s = np.zeros(n, bool)
        s[lo:hi] = True
        out.append(s)
    return out


def test_exact_cover_beats_greedy_where_the_largest_set_is_a_trap():
    # Greedy takes the middle set (60) first, then one half (20 more): 80. The two
    # halves together cover 100.
    sets = _sets(100, (20, 80), (0, 50), (50, 100))
    chosen, share = max_cover(sets, 2)
    assert sorted(chosen) == [1, 2]
    assert share == 1.0
    chosen, share = max_cover(sets, 1)
    assert chosen == [0] and share == 0.6


def test_cover_of_nothing_and_of_disjoint_sets():
    assert max_cover([], 3) == ([], 0.0)
    sets = _sets(10, (0, 2), (2, 5), (5, 6))
    chosen, share = max_cover(sets, 5)
    assert sorted(chosen) == [0, 1, 2] and share == 0.6
