"""Where to put the part on the table so an arm can scan all of it: `place`.

The search runs over the part's table pose T_base_part = Tz(z) · T(x, y) · Rz(yaw) (the part
lies as designed, turned about the vertical and moved). A placement is feasible when every
pose has an in-limit IK solution and each scanning pass keeps one arm configuration; among
feasible ones the worst normalized margin (joint limits, wrist, elbow, shoulder) is
maximized, else the share of the poses reached (weighted: of what they are worth,
`place_weights`). A coarse grid on a subsample of poses, then a pattern search on more of
them (`place_search`), then the full `check_reach` on every pose of the best. In a cell
(`obstacles`), a placement that puts the arm's column into the table block is ranked below
every other, the best candidate at each height of the grid is among the final ones, and
those are ranked on a sample by the poses `fit.fit_to_robot` would keep (each pass as
planned or turned about the beam; the links by `links.check_links`, the sensor body by its
clearance).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from scanplan.core.quantities import PLACE_YAW_STEP_DEG
from scanplan.core.trajectory import Trajectory
from scanplan.robot.base import Robot, pose_arg
from scanplan.robot.flown_poses import flyable_poses, kept_by_pass, most_kept, sensor_clear_both
from scanplan.robot.links import LinkReport, check_links, on_table_z, stands_in_cell
from scanplan.robot.place_search import (
    coarse_grid,
    pattern_search,
    placement_poses,
    placement_scores,
    run_starts,
)
from scanplan.robot.place_weights import checked_weights, sample_poses, weighted_sample
from scanplan.robot.presets import get_robot
from scanplan.robot.reach import ReachReport, check_reach, pass_starts
from scanplan.world.capsule_collision import CellObstacles

_LINK_RANK_POSES = 1500  # poses whose links rank the final candidates
# The search's settings (its yaw step's default is `quantities.PLACE_YAW_STEP_DEG`): the
# poses it scores the coarse grid and the pattern search on, and how many of the grid's best
# it moves on from.
COARSE_POSES, FINE_POSES, KEEP = 48, 256, 6
# Weighted, the poses added to the samples for each view they miss: only those, and few,
# since the coarse grid's cost grows with its sample (the quadrotor's 116 views, every one
# added: placed in 22 s, not 12; only those missed: 16 s).
_COARSE_PER_VIEW, _FINE_PER_VIEW = 1, 2


@dataclass(frozen=True)
class Placement:
    """The best part pose found.

    T_base_part: (4, 4) mm, the `--part-pose` of `scanplan export`.
    report: the full reach check of every pose there; score: worst normalized margin
    (>= 1: everything clear of the thresholds; < 0: not feasible on the search subsample),
    None for a placement judged, not searched (a plan's own).
    links: the arm's links along the path there (None: placed without a cell).
    """

    T_base_part: np.ndarray
    report: ReachReport
    score: float | None
    evaluated: int
    seconds: float
    links: LinkReport | None = None

    @property
    def reachable(self) -> bool:
        """Every pose reached within the joint limits, one configuration per pass."""
        return self.report.reachable

    @property
    def flyable(self) -> bool:
        """Reachable, and no link comes into the cell."""
        return self.reachable and (self.links is None or self.links.clear)

    def binding(self) -> str:
        """What stops the best placement found, the largest count first."""
        r = self.report
        counts = [
            (len(r.unreachable), "poses out of the arm's reach"),
            (len(r.limit_violations), "poses beyond its joint limits"),
            (len(r.config_flips), "configuration flips in a pass or the move into it"),
        ]
        if self.links is not None:
            counts.append((int(self.links.colliding.sum()), "poses with an arm link in the cell"))
            counts.append((len(self.links.moves), "joint moves sweeping a link into the cell"))
        return "; ".join(f"{n} {what}" for n, what in sorted(counts, reverse=True) if n)

    def pose_arg(self) -> str:
        """The placement as `--part-pose` reads it (`base.pose_arg`)."""
        return pose_arg(self.T_base_part)


def _as_printed(T_base_part: np.ndarray) -> np.ndarray:
    """The placement as `base.pose_arg` prints it (µm, millidegrees): the pose that is
    checked is the one the user passes on, so `export` repeats the verdict exactly."""
    x, y, z = np.round(T_base_part[:3, 3], 3)
    yaw = np.radians(np.round(np.degrees(np.arctan2(T_base_part[1, 0], T_base_part[0, 0])), 3))
    T = np.eye(4)
    T[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    T[:3, 3] = x, y, z
    return T


def reach_mm(robot: Robot) -> tuple[float, float]:
    """(horizontal reach of the flange, height of the workspace centre) from FK samples."""
    lim = np.clip(robot.joint_limits, -np.pi, np.pi)
    q = np.random.default_rng(0).uniform(lim[:, 0], lim[:, 1], (4000, 6))
    p = robot.forward(q)[:, :3, 3]
    return float(np.hypot(p[:, 0], p[:, 1]).max()), float(np.median(p[:, 2]))


# In a cell, the seeds at each height: the best this many yaws at least 60° apart (the drone
# on a KR 6 kept 0.886 of its scanning poses from the best yaw per height, 0.916 from three).
PER_HEIGHT_YAWS = 3


def _seeds(
    grid: np.ndarray,
    heights: np.ndarray,
    scores: np.ndarray,
    even_scores: np.ndarray,
    keep: int,
    in_cell: bool,
    on_table: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The coarse placements the pattern search starts from: the best `keep` by either
    score, and in a cell the best few yaws at each height too; and which of them are there
    only as their height's (searched at that height: the margins the search climbs do not
    see the table, and would lift a low placement to where the others are)."""
    # The table top's height (`on_table`) only adds its own seeds: the best are the others'.
    other = grid[:, 2] != (np.nan if on_table is None else on_table)
    ranked = [np.argsort(-np.where(other, v, -np.inf))[:keep] for v in (scores, even_scores)]
    best = np.union1d(*ranked)
    per_height: list[int] = []
    if in_cell:
        for z in heights:
            at = np.flatnonzero(grid[:, 2] == z)
            taken: list[float] = []
            for i in at[np.argsort(-scores[at])]:
                yaw = grid[i, 3]
                if all(abs((yaw - t + np.pi) % (2 * np.pi) - np.pi) > np.pi / 3 for t in taken):
                    per_height.append(int(i))
                    taken.append(yaw)
                if len(taken) == PER_HEIGHT_YAWS:
                    break
    seeds = np.union1d(best, per_height).astype(int)
    return seeds, ~np.isin(seeds, best)


def _best_judged(
    traj: Trajectory,
    arm: Robot,
    tcp: np.ndarray,
    T_part_flange: np.ndarray,
    best: np.ndarray,
    best_scores: np.ndarray,
    centre: np.ndarray,
    obstacles: CellObstacles | None,
    weights: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """The searched candidate (rows of `best`, scored `best_scores`) that keeps the most
    scanning poses flyable (the most of their `weights`), a fully flyable one first, and
    its score: judged on every pose following the branch as a controller would, in a cell
    the arm's links too (on a subsample). Returns `T_base_part` and the search's score."""
    ranked: list[tuple[bool, float, int, np.ndarray, float]] = []
    worth = np.ones(len(traj)) if weights is None else weights
    inv_tcp = np.linalg.inv(tcp)
    order = np.argsort(-best_scores)
    placed = [_as_printed(placement_poses(best[i : i + 1], centre)[0]) for i in order]
    if obstacles is None:
        for rank, T_base_part in enumerate(placed):
            report = check_reach(
                T_base_part @ T_part_flange, arm, swath=traj.swath, scanning=traj.scanning
            )
            good = ~np.isnan(report.joints).any(axis=1)
            counted = traj.scanning if traj.scanning.any() else np.ones(len(traj), bool)
            held = float(worth[good & counted].sum())
            ranked.append(
                (report.reachable, held, -rank, T_base_part, float(best_scores[order[rank]]))
            )
            if report.reachable:
                break
        *_, T_best, score = max(ranked, key=lambda r: r[:3])
        return T_best, score
    # An arm standing in the table cannot be set up: judged only if none stands clear.
    clear = stands_in_cell(arm, np.stack(placed), obstacles)
    if clear.any():
        placed = [T for T, ok in zip(placed, clear, strict=True) if ok]
        order = order[clear]
    # Ranked on the sample by what `fit.fit_to_robot` would keep: each pass as planned or
    # turned about the beam; the full check for the chosen one only. What counts is the
    # scanning kept (a move given up is flown as a joint move).
    sample, sampled = weighted_sample(
        traj, weights, sample_poses(traj, _LINK_RANK_POSES), _FINE_PER_VIEW
    )
    sampled = np.ones(len(sample)) if sampled is None else sampled
    sensor_ok = sensor_clear_both(traj.poses[sample], obstacles)
    swath, scanning = traj.swath[sample], traj.scanning[sample]
    counted = scanning if scanning.any() else np.ones(len(sample), bool)
    # The links only take poses away: what reach and the sensor keep bounds what a
    # placement can keep, so those that cannot beat the best found are not judged (the
    # links cost 20x the reach).
    bounds = []
    for T_base_part in placed:
        planned, turned = flyable_poses(traj, arm, T_base_part, inv_tcp, None, sample)
        bounds.append(
            most_kept(swath, counted * sampled, planned & sensor_ok[0], turned & sensor_ok[1])
        )
    for rank in sorted(range(len(placed)), key=lambda r: (-bounds[r], r)):
        if ranked and bounds[rank] < max(r[1] for r in ranked):
            break
        T_base_part = placed[rank]
        kept = flyable_poses(
            traj, arm, T_base_part, inv_tcp, obstacles, sample, sensor_ok, exact=False,
            choosing=np.ones(len(sample), bool),
        )  # fmt: skip
        good = kept_by_pass(swath, *kept)
        held = float(sampled[good & counted].sum())
        ranked.append((bool(good.all()), held, -rank, T_base_part, float(best_scores[order[rank]])))
    *_, T_best, score = max(ranked, key=lambda r: r[:3])
    return T_best, score


def place(
    traj: Trajectory,
    robot: str | Path | Robot,
    tcp: np.ndarray | None = None,
    height_range_mm: tuple[float, float] | None = None,
    yaw_step_deg: float = PLACE_YAW_STEP_DEG,
    obstacles: CellObstacles | None = None,
    weights: np.ndarray | None = None,
) -> Placement:
    """The part pose on the table from which `robot` reaches every pose of `traj` with the
    most margin (or, when none does, the one reaching the most of the poses' `weights`,
    (n,): what each is worth, e.g. `place_weights.pose_weights`; None: each the same).
    `tcp` is `T_flange_sensor` (mm); `height_range_mm` bounds the part origin's z in the
    base frame (default: the arm's reach around the workspace centre); `obstacles` the cell
    the links must keep clear of (None: links not checked)."""
    started = time.perf_counter()
    arm = get_robot(robot)
    tcp = np.eye(4) if tcp is None else np.asarray(tcp, dtype=np.float64)
    T_best, score, evaluated = best_placement(
        traj, arm, tcp, height_range_mm, yaw_step_deg, obstacles, weights
    )
    T_part_flange = traj.poses @ np.linalg.inv(tcp)
    report = check_reach(T_best @ T_part_flange, arm, swath=traj.swath, scanning=traj.scanning)
    chosen = Placement(T_best, report, score, evaluated, 0.0)
    if obstacles is not None and chosen.reachable:
        links = check_links(
            arm,
            chosen.report.joints,
            obstacles,
            chosen.T_base_part,
            pass_starts(traj.swath, traj.scanning),
        )
        chosen = replace(chosen, links=links)
    return replace(chosen, seconds=time.perf_counter() - started)


def best_placement(
    traj: Trajectory,
    arm: Robot,
    tcp: np.ndarray,
    height_range_mm: tuple[float, float] | None = None,
    yaw_step_deg: float = PLACE_YAW_STEP_DEG,
    obstacles: CellObstacles | None = None,
    weights: np.ndarray | None = None,
) -> tuple[np.ndarray, float, int]:
    """`place`'s search alone, for a caller that checks the placement its own way (the
    planner fits the arm there): (T_base_part, its score, the placements scored)."""
    if len(traj) == 0:
        raise ValueError("cannot place an empty trajectory")
    if not (np.isfinite(yaw_step_deg) and 0 < yaw_step_deg <= 360):
        raise ValueError(f"yaw step must be in (0, 360] degrees, got {yaw_step_deg}")
    weights = checked_weights(weights, len(traj))
    T_part_flange = traj.poses @ np.linalg.inv(tcp)
    reach, z_mid = reach_mm(arm)
    lo, hi = height_range_mm if height_range_mm is not None else (z_mid - reach, z_mid + reach)
    if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
        raise ValueError(f"height range must be LO <= HI in mm, got {lo}, {hi}")
    centre = T_part_flange[:, :2, 3].mean(axis=0)

    # Coarse: a grid along a line out to the arm's reach, every yaw step, a few heights.
    coarse, w = weighted_sample(traj, weights, sample_poses(traj, COARSE_POSES), _COARSE_PER_VIEW)
    step = reach / 6
    heights = np.linspace(lo, hi, 7) if hi > lo else np.array([lo])
    top = None  # and, in a cell, standing on the table's top
    if obstacles is not None and obstacles.table_block is not None:
        top = on_table_z(arm, obstacles.table_block, obstacles.clearance_mm)
        heights = np.union1d(heights, [top] if top is not None and lo <= top <= hi else [])
    grid = coarse_grid(reach, step / 2, heights, yaw_step_deg)
    placements = placement_poses(grid, centre)
    scores = placement_scores(
        arm, T_part_flange[coarse], run_starts(traj, coarse), placements, obstacles, w
    )
    # And on evenly spaced poses alone: a pass's first and last poses can outweigh the scanning
    # in the sample above (the drone on a UR5e kept 0.87 of its poses from one, 0.75 from it).
    even = np.linspace(0, len(traj) - 1, min(COARSE_POSES, len(traj))).round().astype(int)
    even, w = weighted_sample(traj, weights, even, _COARSE_PER_VIEW)
    even_scores = placement_scores(
        arm, T_part_flange[even], run_starts(traj, even), placements, obstacles, w
    )
    evaluated = 2 * len(grid)

    # Fine: pattern search from the best few, on more poses; all candidates move at once.
    fine, w = weighted_sample(traj, weights, sample_poses(traj, FINE_POSES), _FINE_PER_VIEW)
    starts = run_starts(traj, fine)
    # Seeds: the best few, and in a cell the best yaws at each height too, since the margins
    # favour heights from which the links may not clear the table (ranked at the end).
    seeds, held = _seeds(grid, heights, scores, even_scores, KEEP, obstacles is not None, top)
    best = grid[seeds]
    placed = placement_poses(best, centre)
    best_scores = placement_scores(arm, T_part_flange[fine], starts, placed, obstacles, w)
    delta = np.array([step / 2, step / 2, max((hi - lo) / 12, 1.0), np.radians(yaw_step_deg) / 2])
    best, best_scores, searched = pattern_search(
        arm,
        T_part_flange[fine],
        starts,
        centre,
        obstacles,
        best,
        best_scores,
        delta,
        (lo, hi),
        held,
        w,
    )
    evaluated += searched

    # The answer is judged on every pose (in a cell the arm's links too).
    T_best, score = _best_judged(
        traj, arm, tcp, T_part_flange, best, best_scores, centre, obstacles, weights
    )
    return T_best, score, evaluated
