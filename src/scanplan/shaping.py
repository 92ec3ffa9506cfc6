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
    """Shape a target profile sampled on `grid_mm` so |slope| <= `max_rate_per_mm`."""

    def shape(
        self, grid_mm: np.ndarray, values: np.ndarray, max_rate_per_mm: float
    ) -> np.ndarray: ...


def _rate_limit(values: np.ndarray, max_step: float, backwards: bool = False) -> np.ndarray:
    """One pass of |v[i] - v[i-1]| <= max_step (a sequential recurrence, over grid cells)."""
    v = values[::-1].copy() if backwards else values.copy()
    # Where v follows the values, it changes nothing until a step steeper than max_step;
    # from there the recurrence runs until it meets the values again.
    steep = np.flatnonzero(np.abs(np.diff(v)) > max_step) + 1
    i = 0  # v[i] is on the values
    for k in steep:
        if k <= i:
            continue
        for i in range(k, len(v)):
            follows = v[i]
            v[i] = min(max(v[i], v[i - 1] - max_step), v[i - 1] + max_step)
            if v[i] == follows:
                break
    return v[::-1] if backwards else v


@dataclass(frozen=True)
class CentredLookahead:
    """Gaussian pre-smoothing (`smooth_mm`, 0 = none), then a rate limit centred on each
    feature: the mean of a forward (lagging) and a backward (leading) pass at twice the rate
    puts each ramp half before and half after a step, then a last pass makes the rate exact.
    Symmetric costs (R_D, R_α) make the centred ramp the least costly one."""

    smooth_mm: float = 0.0

    def shape(self, grid_mm, values, max_rate_per_mm):
        values = np.asarray(values, dtype=np.float64)
        if len(values) < 2:
            return values.copy()
        cell = float(np.mean(np.diff(grid_mm)))
        if self.smooth_mm > 0:
            values = gaussian_filter1d(values, self.smooth_mm / cell, mode="nearest")
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
        values = np.asarray(values, dtype=np.float64)
        if len(values) < 2:
            return values.copy()
        cell = float(np.mean(np.diff(grid_mm)))
        step = max(max_rate_per_mm * cell, (values.max() - values.min()) / self.max_states)
        if step <= 0:
            return values.copy()
        lo = float(values.min())
        levels = lo + step * np.arange(int(math.ceil((values.max() - lo) / step)) + 1)
        miss = np.abs(levels[None, :] - values[:, None])
        # Beyond the cap, a slight pull towards the target still breaks ties.
        cost = np.minimum(miss**2, self.cap**2) + 1e-3 * self.cap * miss
        # Forward: the best total reaching each level, from itself or a neighbour (the
        # 3-wide running minimum); backward: the neighbour each step came from, earliest
        # of the tied (level −1, 0, +1).
        totals = np.empty((len(values), len(levels)))
        totals[0] = cost[0]
        for i in range(1, len(values)):
            row = totals[i]
            prev = totals[i - 1]
            np.minimum(prev[1:], prev[:-1], out=row[1:])  # a 3-wide running minimum
            row[0] = prev[0]
            np.minimum(row[:-1], prev[1:], out=row[:-1])
            row += cost[i]
        path = np.zeros(len(values), np.int64)
        path[-1] = int(np.argmin(totals[-1]))
        padded = np.pad(totals, ((0, 0), (1, 1)), constant_values=np.inf)
        for i in range(len(values) - 1, 0, -1):
            j = path[i]
            path[i - 1] = j - 1 + int(np.argmin(padded[i - 1, j : j + 3]))
        return levels[path]
