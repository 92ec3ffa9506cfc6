"""The per-row products the scan quantities are made of: the same bits as numpy's reductions
(D, α and Δs, and with them every plan, must not move when they are made faster)."""

from __future__ import annotations

import numpy as np

from scanplan.core.quantities import advance, dot_rows, norm_rows


def test_row_products_are_numpys_reductions_to_the_last_bit():
    rng = np.random.default_rng(7)
    a = rng.normal(size=(2000, 17, 3)) * 10.0 ** rng.uniform(-4, 4, (2000, 17, 3))
    b = rng.normal(size=(17, 3))
    a[rng.random((2000, 17)) < 0.1] = np.nan
    np.testing.assert_array_equal(dot_rows(a, b), np.sum(a * b, axis=-1))
    np.testing.assert_array_equal(norm_rows(a), np.linalg.norm(a, axis=-1))


def test_advance_counts_the_columns_valid_in_both_profiles():
    """Two profiles 2 mm apart along u, one 1 mm back on another column: the mean signed
    advance of the columns valid in both; none in common is NaN."""
    u = np.array([1.0, 0.0, 0.0])
    prev = np.zeros((1, 3, 3))
    nxt = prev.copy()
    nxt[0, :, 0] = [2.0, 2.0, -1.0]
    valid_prev = np.array([[True, True, True]])
    valid_next = np.array([[True, False, True]])
    nxt[0, 1] = np.nan  # an invalid column's point
    assert advance(prev, valid_prev, nxt, valid_next, u)[0] == 0.5
    assert np.isnan(advance(prev, valid_prev, nxt, ~valid_prev, u)[0])
