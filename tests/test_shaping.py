"""The look-ahead shapers' recurrences, which skip the stretches where nothing is clipped:
the same result as running the recurrence over every grid cell."""

from __future__ import annotations

import numpy as np

from scanplan.shaping import CentredLookahead, _rate_limit


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
