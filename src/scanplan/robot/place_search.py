"""The placement search's moves and scores (`place`): placements as rows (x, y, z, yaw)
turned into part poses (`placement_poses`), the coarse grid they start from
(`coarse_grid`), each scored by the margins of its inverse kinematics over sampled poses
(`placement_scores`), and the pattern search that improves them all at once
(`pattern_search`).
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from scanplan.core.limits import MAX_PLACEMENTS, check_count
from scanplan.core.trajectory import Trajectory
from scanplan.robot.base import Robot
from scanplan.robot.links import stands_in_cell
from scanplan.robot.nearest_joints import fit_limits, limit_margin, reduce_last_axis
from scanplan.world.capsule_collision import CellObstacles

# Margins that count as "clear": 5° from a limit or a wrist/elbow singularity, 20 mm from
# the shoulder one (the thresholds `check_reach` flags).
_MARGIN_REF = np.array([np.sin(np.radians(5.0)), np.sin(np.radians(5.0)), 20.0])
_LIMIT_REF_RAD = np.radians(5.0)
_CHUNK_POSES = 60_000  # poses per IK call: ~25 MB per chunk, a chunk per core at once


def run_starts(traj: Trajectory, keep: np.ndarray) -> np.ndarray:
    """Start indices (into the kept poses) of runs that must share one arm configuration:
    each scanning pass is one run, each transition pose a run of its own."""
    s, w = traj.scanning[keep], traj.swath[keep]
    same = s[1:] & s[:-1] & (w[1:] == w[:-1])
    return np.flatnonzero(np.r_[True, ~same])


def placement_poses(params: np.ndarray, centre_xy: np.ndarray) -> np.ndarray:
    """(P, 4, 4) T_base_part for rows (x, y, z, yaw rad); (x, y) is where the path's centre
    lands."""
    x, y, z, yaw = params.T
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.zeros((len(params), 4, 4))
    T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = c, -s, s, c
    T[:, 2, 2] = T[:, 3, 3] = 1.0
    T[:, 0, 3] = x - (c * centre_xy[0] - s * centre_xy[1])
    T[:, 1, 3] = y - (s * centre_xy[0] + c * centre_xy[1])
    T[:, 2, 3] = z
    return T


def placement_scores(
    robot: Robot,
    T_part_flange: np.ndarray,
    starts: np.ndarray,
    T_base_part: np.ndarray,
    obstacles: CellObstacles | None = None,
    weights: np.ndarray | None = None,
) -> np.ndarray:
    """(P,) rank of each placement: the worst normalized margin (>= 0) if every pose is
    reachable with one configuration per run, else reachable fraction - 2 (in [-2, -1]),
    the fraction of the poses' `weights` (None: of the poses); 4 less where the arm's
    column stands in the table block of `obstacles`."""
    m = len(T_part_flange)
    limits = robot.joint_limits
    out = np.empty(len(T_base_part))
    # Chunks of placements on a thread per core (numpy lets go of the GIL on arrays this
    # size): the search runs while the view workers wait.
    threads = os.cpu_count() or 1
    per = max(1, min(_CHUNK_POSES // m, -(-len(T_base_part) // threads)))

    def score(k: int) -> None:
        T = T_base_part[k : k + per, None] @ T_part_flange[None]  # (p, m, 4, 4)
        p = len(T)
        q = robot.inverse(T.reshape(-1, 4, 4))  # (p·m, 8, 6)
        q, inside = fit_limits(q, limits)
        inside &= ~np.isnan(q).any(axis=-1)
        margin = np.abs(robot.singularity_terms(q)) / _MARGIN_REF
        value = np.minimum(
            reduce_last_axis(margin, np.minimum), limit_margin(q, limits) / _LIMIT_REF_RAD
        )
        value = np.where(inside, value, -np.inf).reshape(p, m, 8)
        per_run = np.minimum.reduceat(value, starts, axis=1).max(axis=2)  # (p, runs)
        worst = per_run.min(axis=1)
        reached = inside.reshape(p, m, 8).any(axis=2)
        fraction = reached.mean(axis=1) if weights is None else reached @ weights / weights.sum()
        out[k : k + p] = np.where(np.isfinite(worst), worst, fraction - 2.0)

    with ThreadPoolExecutor(max_workers=threads) as pool:
        list(pool.map(score, range(0, len(T_base_part), per)))
    if obstacles is None:
        return out
    clear = stands_in_cell(robot, T_base_part, obstacles)
    return np.where(clear, out, out - 4.0)


def coarse_grid(reach: float, step: float, heights: np.ndarray, yaw_step_deg: float) -> np.ndarray:
    """(P, 4) rows (x, y, z, yaw rad): `step` apart along the base's +x axis out to `reach`,
    every yaw step, at each of `heights`. One line, not the disc: the part and its cell turned
    about the base's vertical axis give the arm the same joints but the first, turned as
    much, so the disc only repeats the line with that joint's margin changed (the pattern
    search moves off it); the line on +x keeps it mid-range (first joints turn ±170-180°)."""
    radii = np.arange(0.0, reach + 1e-9, step)
    n_yaws = math.ceil(3 * 360.0 / yaw_step_deg - 1e-9)
    check_count(  # before the grid is allocated
        len(radii) * len(heights) * n_yaws,
        MAX_PLACEMENTS,
        f"candidate placements (yaw step {yaw_step_deg:g} deg)",
        "give a larger yaw step",
    )
    # Yaw three times finer: the disc's positions round the base turned the part against
    # the arm in between its yaw steps, which the line does not.
    yaws = np.radians(np.arange(0.0, 360.0 - 1e-9, yaw_step_deg / 3))
    r, z, a = np.meshgrid(radii, heights, yaws, indexing="ij")
    return np.stack([r.ravel(), np.zeros(r.size), z.ravel(), a.ravel()], axis=1)


def pattern_search(
    robot: Robot,
    T_part_flange: np.ndarray,
    starts: np.ndarray,
    centre: np.ndarray,
    obstacles: CellObstacles | None,
    best: np.ndarray,
    best_scores: np.ndarray,
    delta: np.ndarray,
    height_range: tuple[float, float],
    held_height: np.ndarray | None = None,
    weights: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Improve every candidate row of `best` (scored `best_scores`) at once: each round tries
    a step of `delta` either way along x, y, z and yaw (z kept in `height_range`, and not
    moved for the rows `held_height` marks; the poses weighted by `weights`), keeps the best
    that scores higher, and halves the steps when none does, until they are under 4 mm or 24
    rounds have run. Returns the candidates, their scores and how many were scored."""
    lo, hi = height_range
    evaluated = 0
    moves = np.concatenate([np.zeros((1, 4)), np.eye(4), -np.eye(4)])
    held = np.zeros(len(best), bool) if held_height is None else held_height
    # A candidate that did not improve at these steps would try the same placements again
    # (the same scores) until the steps change: only the others are scored.
    stale = np.zeros(len(best), bool)
    best, best_scores = best.copy(), best_scores.copy()
    for _ in range(24):
        rows = np.flatnonzero(~stale)
        trial = best[rows, None] + moves[None] * delta
        trial[..., 2] = np.clip(trial[..., 2], lo, hi)
        trial[held[rows], :, 2] = best[rows[held[rows]], None, 2]
        flat = trial.reshape(-1, 4)
        s = placement_scores(
            robot, T_part_flange, starts, placement_poses(flat, centre), obstacles, weights
        )
        evaluated += len(flat)
        s = s.reshape(len(rows), len(moves))
        pick = s.argmax(axis=1)
        improved = s[np.arange(len(rows)), pick] > best_scores[rows] + 1e-9
        best[rows] = np.where(improved[:, None], trial[np.arange(len(rows)), pick], best[rows])
        best_scores[rows] = np.maximum(best_scores[rows], s.max(axis=1))
        stale[rows[~improved]] = True
        if not improved.any():
            delta = delta / 2
            stale[:] = False
            if delta[0] < 4.0:  # a few mm move no pose in or out of reach worth the rounds
                break
    return best, best_scores, evaluated


__all__ = ["coarse_grid", "pattern_search", "placement_poses", "placement_scores", "run_starts"]
