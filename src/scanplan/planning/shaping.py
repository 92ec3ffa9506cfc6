"""Look-ahead shapers: a target profile along a pass (pitch, roll, height) shaped so its rate
stays within the per-step limits, anticipating steps and slopes instead of lagging behind
them. Used by the geometric planner and by the in-spec band prediction of adaptive passes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy.ndimage import gaussian_filter1d

# The pitch rate the shapers allow, as a fraction of 1/W_d rad per mm of advance (a pitch
# step swings the footprint by W_d·Δθ), and the roll rate as a fraction of Δφ_max per
# Δs_opt: headroom below the step limits for the tracker.
PITCH_LEVER = 0.6
ROLL_RATE = 0.8


class Lookahead(Protocol):
    """Shape a target profile sampled on `grid_mm` so |slope| <= `max_rate_per_mm`; values
    (k,), or (b, k) for b profiles on the same grid."""

    def shape(
        self, grid_mm: np.ndarray, values: np.ndarray, max_rate_per_mm: float
    ) -> np.ndarray: ...


def _rate_limit(values: np.ndarray, max_step: float, backwards: bool = False) -> np.ndarray:
    """One pass of |v[i] - v[i-1]| <= max_step along the last axis of (k,) or (b, k) values
    (a sequential recurrence, over grid cells)."""
    v = values[..., ::-1].copy() if backwards else values.copy()
    rows = v.reshape(-1, v.shape[-1])  # a view of the copy
    # Where v follows the values, it changes nothing until a step steeper than max_step;
    # from there the recurrence runs until it meets the values again.
    row_of, steep = np.nonzero(np.abs(np.diff(rows, axis=1)) > max_step)
    for r in np.unique(row_of):
        row = rows[r]
        i = 0  # row[i] is on the values
        for k in steep[row_of == r] + 1:
            if k <= i:
                continue
            for i in range(k, len(row)):
                follows = row[i]
                row[i] = min(max(row[i], row[i - 1] - max_step), row[i - 1] + max_step)
                if row[i] == follows:
                    break
    return v[..., ::-1] if backwards else v


@dataclass(frozen=True)
class CentredLookahead:
    """Gaussian pre-smoothing (`smooth_mm`, 0 = none), then a rate limit centred on each
    feature: the mean of a forward (lagging) and a backward (leading) pass at twice the rate
    puts each ramp half before and half after a step, then a last pass makes the rate exact.
    Symmetric costs (R_D, R_α) make the centred ramp the least costly one."""

    smooth_mm: float = 0.0

    def shape(self, grid_mm, values, max_rate_per_mm):
        """Also of each row of (b, k) values at once (the in-spec bands of a raster's pass
        centres)."""
        values = np.asarray(values, dtype=np.float64)
        if values.shape[-1] < 2:
            return values.copy()
        cell = float(np.mean(np.diff(grid_mm)))
        if self.smooth_mm > 0:
            values = gaussian_filter1d(values, self.smooth_mm / cell, axis=-1, mode="nearest")
        step = max_rate_per_mm * cell
        both = 0.5 * (_rate_limit(values, 2 * step) + _rate_limit(values, 2 * step, True))
        return _rate_limit(both, step)


@dataclass(frozen=True)
class RobustLookahead:
    """The rate-limited profile closest to the target, found exactly by dynamic programming:
    minimize Σ min((v_i − t_i)², cap²) (+ a slight pull beyond the cap) subject to
    |v_i − v_{i−1}| ≤ rate·cell. The cap (a truncated square) lets the profile give up on a
    feature too short to follow at this rate (a drone's nose, a narrow crease) instead of
    dragging the ramp into the surface around it, which a centred ramp does. Values are
    quantized to rate·cell (the exact reachable set of a rate-limited walk from a grid
    start)."""

    cap: float = math.radians(12.0)
    max_states: int = 4000

    def shape(self, grid_mm, values, max_rate_per_mm):
        """Also of each row of (b, k) values at once, in one dynamic programme (the in-spec
        bands of a raster shape the pitch of 20-100 pass centres: a call each was 15 % of a
        machined part's view choice). Every row gets as many levels as the row that needs
        most: a level above all of a row's values costs more than the one below it, so no
        least-cost path of that row takes it."""
        given = np.asarray(values, dtype=np.float64)
        values = given.reshape(-1, given.shape[-1])
        b, k = values.shape
        if k < 2:
            return given.copy()
        cell = float(np.mean(np.diff(grid_mm)))
        lo, hi = values.min(axis=1), values.max(axis=1)
        step = np.maximum(max_rate_per_mm * cell, (hi - lo) / self.max_states)
        flat = step <= 0  # a constant row on no rate: nothing to shape
        step = np.where(flat, 1.0, step)
        count = np.where(flat, 1, np.ceil((hi - lo) / step).astype(np.int64) + 1)
        levels = lo[:, None] + step[:, None] * np.arange(int(count.max()))
        miss = np.abs(levels[:, None, :] - values[:, :, None])
        # Beyond the cap, a slight pull towards the target still breaks ties.
        cost = np.minimum(miss**2, self.cap**2) + 1e-3 * self.cap * miss
        # Forward: the best total reaching each level, from itself or a neighbour (the
        # 3-wide running minimum; levels padded with an infinite one at each end); backward:
        # the neighbour each step came from, the earliest of the tied (level −1, 0, +1).
        totals = np.full((b, k, levels.shape[1] + 2), np.inf)
        totals[:, 0, 1:-1] = cost[:, 0]
        for i in range(1, k):
            prev, row = totals[:, i - 1], totals[:, i, 1:-1]
            np.minimum(prev[:, :-2], prev[:, 1:-1], out=row)
            np.minimum(row, prev[:, 2:], out=row)
            row += cost[:, i]
        path = np.empty((b, k), np.int64)
        path[:, -1] = np.argmin(totals[:, -1], axis=1)
        for r in range(b):  # scalar steps: a numpy call costs more than one step
            t, j = totals[r], int(path[r, -1])  # j in the padded levels
            for i in range(k - 2, -1, -1):
                below, here, above = t[i, j - 1], t[i, j], t[i, j + 1]
                j += -1 if below <= min(here, above) else (0 if here <= above else 1)
                path[r, i] = j
        path -= 1
        shaped = np.take_along_axis(levels, path, axis=1)
        return np.where(flat[:, None], values, shaped).reshape(given.shape)
