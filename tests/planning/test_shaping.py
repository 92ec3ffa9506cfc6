"""The look-ahead shapers' recurrences, which skip the stretches where nothing is clipped:
the same result as running the recurrence over every grid cell."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from scanplan.planning.shaping import CentredLookahead, RobustLookahead, _rate_limit


def every_cell(values: np.ndarray, max_step: float, backwards: bool = False) -> np.ndarray:
    """|v[i] - v[i-1]| <= max_step, the recurrence run over every cell."""
    v = values[::-1].copy() if backwards else values.copy()
    for i in range(1, len(v)):
        v[i] = min(max(v[i], v[i - 1] - max_step), v[i - 1] + max_step)
    return v[::-1] if backwards else v


def test_the_rate_limit_is_the_recurrence_over_every_cell():
    rng = np.random.default_rng(3)
    clipped = 0
    for _ in range(300):
        n = int(rng.integers(1, 200))
        values = np.cumsum(rng.normal(0.0, 0.3, n))
        values[rng.integers(0, n) :] += rng.normal(0.0, 10.0)  # a step somewhere
        if rng.random() < 0.2:
            values[rng.integers(0, n)] = np.nan  # a hole passes through
        step = float(rng.uniform(0.05, 2.0))
        for backwards in (False, True):
            want = every_cell(values, step, backwards)
            got = _rate_limit(values, step, backwards)
            np.testing.assert_array_equal(got, want)
            clipped += int(not np.array_equal(want, values, equal_nan=True))
    assert clipped > 100  # the recurrence was exercised, not only skipped


def test_a_centred_ramp_puts_half_of_a_step_before_it():
    grid = np.arange(0.0, 100.0, 1.0)
    values = np.where(grid < 50.0, 0.0, 10.0)
    shaped = CentredLookahead().shape(grid, values, 0.5)
    assert np.abs(np.diff(shaped)).max() <= 0.5 + 1e-12
    ramp = np.flatnonzero((shaped > 1e-9) & (shaped < 10.0 - 1e-9))
    assert abs(grid[ramp].mean() - 49.5) <= 1.0  # centred on the step
    assert shaped[0] == 0.0 and shaped[-1] == 10.0


def test_the_robust_shaper_finds_the_least_costly_rate_limited_path():
    """Against every path over its levels (a few cells, a few levels): the dynamic programme
    returns one of the least cost, and it moves at most one level a cell."""
    rng = np.random.default_rng(5)
    shaper = RobustLookahead(cap=0.5)
    for _ in range(40):
        values = rng.uniform(0.0, 1.2, 5)
        shaped = shaper.shape(np.arange(5.0), values, 0.25)
        levels = values.min() + 0.25 * np.arange(int(np.ceil(np.ptp(values) / 0.25)) + 1)

        def cost(path, levels=levels, values=values):
            miss = np.abs(levels[list(path)] - values)
            return float((np.minimum(miss**2, 0.25) + 1e-3 * 0.5 * miss).sum())

        best = min(
            cost(p)
            for p in itertools.product(range(len(levels)), repeat=5)
            if all(abs(a - b) <= 1 for a, b in itertools.pairwise(p))
        )
        path = np.rint((shaped - levels[0]) / 0.25).astype(int)
        assert np.allclose(levels[path], shaped)
        assert np.abs(np.diff(path)).max() <= 1
        assert cost(path) == pytest.approx(best, rel=1e-12)


def test_a_batch_of_profiles_is_shaped_as_each_alone():
    """Rows of different spans (so different numbers of levels, padded in the batch), shaped
    together by both shapers, equal each row shaped on its own, to the last bit."""
    rng = np.random.default_rng(11)
    grid = np.arange(0.0, 60.0 * 20.0, 20.0)
    rows = np.stack(
        [np.cumsum(rng.normal(0.0, s, len(grid))) for s in (0.002, 0.05, 0.2, 0.0, 0.1)]
    )
    rows[1, 30:] += 0.6  # a step
    for shaper, rate in ((RobustLookahead(), 0.0015), (CentredLookahead(), 0.003)):
        together = shaper.shape(grid, rows, rate)
        alone = np.stack([shaper.shape(grid, row, rate) for row in rows])
        np.testing.assert_array_equal(together, alone)
        assert not np.array_equal(together, rows)  # something was shaped
