"""Where the arm stands with its external axes: the placement searched with a turntable
(the arm's distance from its axis and height) or a track (across it, up or down, or the arm
hung from an overhead one), each stand judged by what the best per-view settings keep.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scanplan.core.trajectory import Trajectory
from scanplan.robot.axes import ExternalAxes
from scanplan.robot.axes_fit import (
    SAMPLE_POSES,
    candidates,
    hangs,
    long_side,
    resolved,
    view_blocks,
)
from scanplan.robot.axes_kept import kept_each, reach_bound_each
from scanplan.robot.base import Robot
from scanplan.robot.flyable import stands_clear
from scanplan.robot.place import place, reach_mm
from scanplan.robot.place_weights import sample_poses
from scanplan.robot.presets import get_robot
from scanplan.world.capsule_collision import CellObstacles
from scanplan.world.part import Part

# The arm's column stands at least this far outside the turntable's disk.
BESIDE_DISK_MM = 150.0
# With a track, the placement is searched across it and in height about the arm's own.
TRACK_ACROSS_MM = np.arange(-400.0, 401.0, 100.0)
TRACK_HEIGHTS_MM = np.arange(-300.0, 301.0, 150.0)
# Hung from an overhead track: the base this far above the part's top, and beside the part's
# centre line across the track.
OVERHEAD_HEIGHTS_MM = np.array([300.0, 450.0, 600.0, 800.0, 1000.0])
OVERHEAD_ACROSS_MM = np.array([-300.0, -150.0, 0.0, 150.0, 300.0])
# An overhead track (a gantry over the table) is chosen over a floor one only when it keeps
# this much more of the sampled scanning poses: a floor track is the simpler cell.
OVERHEAD_GAIN = 0.05
# The placements judged again with the arm's links: those within this share of the best
# on reach alone (many tie there; the links tell them apart).
LINK_CHECKED_WITHIN = 0.1
# Each view of those placements judged again at the settings reach alone ranked first.
LINK_SETTINGS = 6


def place_on_axes(
    traj: Trajectory,
    robot: str | Path | Robot,
    tcp: np.ndarray,
    axes: ExternalAxes,
    part: Part,
    T_base_part: np.ndarray,
    obstacles: CellObstacles | None = None,
) -> tuple[np.ndarray, ExternalAxes]:
    """The placement (and the axes' choices) from which the arm with its axes flies most of
    `traj`'s scanning: from `T_base_part` (the arm's own placement for the plan), for a
    turntable also the part's axis at distances and heights around the arm's reach (the
    arm's column outside the disk), for a track the part moved across the track and up or
    down, and the arm hung from an overhead track over the part (`overhead_tries`, unless
    the track is given as a floor one); each judged by the scanning poses the best per-view
    settings keep (reach and limits, on a sample), the arm's column clear of the table. An
    overhead track is taken only when it keeps `OVERHEAD_GAIN` more than the floor's best."""
    arm = get_robot(robot)
    inv_tcp = np.linalg.inv(tcp)
    floor: list[np.ndarray] = []
    mount = None if axes.track is None else axes.track.mount
    if mount != "overhead":
        floor.append(np.asarray(T_base_part, dtype=np.float64))
    if axes.turntable is not None and mount != "overhead":
        reach, z_mid = reach_mm(arm)
        point = resolved(axes, part, T_base_part, traj).turntable.axis_point_mm  # type: ignore[union-attr]
        beside = axes.turntable.radius_mm + BESIDE_DISK_MM
        for r in np.linspace(max(0.3 * reach, beside), max(0.8 * reach, beside + 100.0), 6):
            for z in z_mid + np.linspace(-0.5, 0.2, 5) * reach:
                T = np.eye(4)
                T[:3, 3] = np.array([r, 0.0, z]) - np.asarray(point)
                floor.append(T)
    if axes.track is not None and mount != "overhead":  # nearer or farther, higher, lower
        d = np.asarray(resolved(axes, part, T_base_part, traj).track.direction)  # type: ignore[union-attr]
        across = np.array([-d[1], d[0], 0.0])
        for u in TRACK_ACROSS_MM:
            for z in TRACK_HEIGHTS_MM:
                T = np.array(T_base_part, dtype=np.float64)
                T[:3, 3] += u * across + [0.0, 0.0, z]
                floor.append(T)
    overhead = [] if axes.track is None or mount == "floor" else overhead_tries(traj, part)
    if obstacles is not None:  # the arm's column beside the table, not in it, all along its rail

        def clear(tries: list[np.ndarray]) -> list[np.ndarray]:
            return [
                T for T in tries if stands_clear(arm, T, resolved(axes, part, T, traj), obstacles)
            ]

        # None clear: the arm's own placement, which export will refuse with its reason.
        floor, overhead = clear(floor), clear(overhead)
        if not floor and not overhead:
            floor = [np.asarray(T_base_part, dtype=np.float64)]
    best, best_score = _best_placement(traj, arm, inv_tcp, axes, part, floor, obstacles)
    if overhead:
        high, high_score = _best_placement(traj, arm, inv_tcp, axes, part, overhead, obstacles)
        if best is None or high_score > best_score + OVERHEAD_GAIN:
            best = high
    if best is None:  # every stand in the turntable: the arm's own, which export will refuse
        best = np.asarray(T_base_part, dtype=np.float64)
    return best, resolved(axes, part, best, traj)


def overhead_tries(traj: Trajectory, part: Part) -> list[np.ndarray]:
    """Placements (`T_base_part`) of the arm hung upside down from an overhead track over
    the part: its base `OVERHEAD_HEIGHTS_MM` above the part's top, over the part's centre
    line along its long side and `OVERHEAD_ACROSS_MM` beside it, its x axis along or
    across that side."""
    lo, hi = part.bounds
    d = long_side(traj, np.eye(4))
    d = np.array([1.0, 0.0, 0.0]) if d is None else d
    across = np.array([-d[1], d[0], 0.0])
    down = np.array([0.0, 0.0, -1.0])
    out = []
    for x in (d, across):
        R = np.column_stack([x, np.cross(down, x), down])
        for h in OVERHEAD_HEIGHTS_MM:
            for u in OVERHEAD_ACROSS_MM:
                T_part_base = np.eye(4)
                T_part_base[:3, :3] = R
                T_part_base[:3, 3] = (lo + hi) / 2 + u * across
                T_part_base[2, 3] = hi[2] + h
                out.append(np.linalg.inv(T_part_base))
    return out


def _best_placement(
    traj: Trajectory,
    arm: Robot,
    inv_tcp: np.ndarray,
    axes: ExternalAxes,
    part: Part,
    tries: list[np.ndarray],
    obstacles: CellObstacles | None,
) -> tuple[np.ndarray | None, float]:
    """(the placement among `tries` whose best per-view settings keep most of a sample of
    `traj`'s scanning poses, that share); (None, -1) when none is tried. Each is judged
    on reach and limits, then those near the best also with the arm's links (the quick
    test) against `obstacles`: an arm standing amid the part, or hung low over it,
    reaches it all."""
    best, best_score = None, -1.0
    sample = sample_poses(traj, 4 * SAMPLE_POSES)
    sub = traj.subset(np.isin(np.arange(len(traj)), sample))
    stands: list[tuple[np.ndarray, ExternalAxes]] = []
    for T in tries:
        choice = resolved(axes, part, T, traj)
        t = choice.turntable
        if t is not None and t.axis_point_mm is not None and not hangs(T):
            base = np.linalg.inv(T)[:3, 3]
            if np.hypot(*(base - t.axis_point_mm)[:2]) < t.radius_mm + BESIDE_DISK_MM:
                continue  # the arm's column in the turntable
        stands.append((T, choice))
    # Judged from the highest bound on what a stand keeps (its inverse kinematics alone)
    # down, until the bound falls short of what the judging after this one looks at (within
    # LINK_CHECKED_WITHIN of the best with the links, the best without): the same scores
    # for every stand that matters, the others not judged.
    bounds = [_reach_bound_share(sub, arm, T, inv_tcp, choice) for T, choice in stands]
    margin = LINK_CHECKED_WITHIN if obstacles is not None else 0.0
    judged: dict[int, tuple[float, list[np.ndarray]]] = {}
    top = -np.inf
    for k in np.argsort(-np.asarray(bounds), kind="stable"):
        if bounds[k] < top - margin - 1e-9:
            break
        judged[k] = _kept_share(sub, arm, stands[k][0], inv_tcp, None, stands[k][1])
        top = max(top, judged[k][0])
    scored = [(*judged[k], stands[k][0]) for k in sorted(judged)]
    scored.sort(key=lambda st: -st[0])
    if obstacles is not None and scored:  # the links on those near the best
        top = scored[0][0]
        scored = [
            (
                *_kept_share(
                    sub, arm, T, inv_tcp, obstacles, resolved(axes, part, T, traj), settings
                ),
                T,
            )
            for score, settings, T in scored
            if score >= top - LINK_CHECKED_WITHIN
        ]
    for score, _, T in scored:
        if score > best_score + 1e-9:
            best, best_score = T, score
    return best, best_score


def _kept_share(
    sub: Trajectory,
    arm: Robot,
    T: np.ndarray,
    inv_tcp: np.ndarray,
    obstacles: CellObstacles | None,
    axes: ExternalAxes,
    tried: list[np.ndarray] | None = None,
) -> tuple[float, list[np.ndarray]]:
    """The share of `sub`'s scanning poses the best per-view settings of `axes` keep with
    the arm at `T` (`kept_each`), and each view's `LINK_SETTINGS` best settings. tried: the
    settings to judge each view on (all by default: those the reach alone ranked first,
    when the links judge them again)."""
    every = candidates(axes, arm, coarse=True)
    jobs = [
        (every if tried is None else tried[k], np.flatnonzero(block & sub.scanning))
        for k, block in enumerate(view_blocks(sub))
    ]
    score, best = 0.0, []
    for (settings, index), kept in zip(
        jobs, kept_each(sub, arm, T, inv_tcp, obstacles, axes, jobs), strict=True
    ):
        if not len(index) or not len(settings):
            best.append(settings[:0])
            continue
        score += kept.max()
        best.append(settings[_first(kept, LINK_SETTINGS)])
    return score / max(int(sub.scanning.sum()), 1), best


def _reach_bound_share(
    sub: Trajectory, arm: Robot, T: np.ndarray, inv_tcp: np.ndarray, axes: ExternalAxes
) -> float:
    """At least `_kept_share`'s share without obstacles (`reach_bound_each` per view)."""
    every = candidates(axes, arm, coarse=True)
    jobs = [(every, np.flatnonzero(block & sub.scanning)) for block in view_blocks(sub)]
    bounds = reach_bound_each(sub, arm, T, inv_tcp, axes, jobs)
    most = sum(float(b.max()) for (_, index), b in zip(jobs, bounds, strict=True) if len(index))
    return most / max(int(sub.scanning.sum()), 1)


def _first(scores: np.ndarray, n: int) -> np.ndarray:
    """The indices of the n best `scores`; where more tie for the best, n spread evenly
    among them (settings far apart differ most in where the links go)."""
    order = np.argsort(-scores, kind="stable")
    tied = order[scores[order] >= scores.max() - 1e-9]
    if len(tied) > n:
        return tied[np.linspace(0, len(tied) - 1, n).round().astype(int)]
    return order[:n]


def arm_on_axes(
    traj: Trajectory,
    robot: str | Path,
    tcp: np.ndarray,
    T_base_part: np.ndarray | None,
    axes: ExternalAxes,
    part: Part,
    obstacles: CellObstacles | None,
) -> tuple[np.ndarray, ExternalAxes]:
    """(T_base_part, the axes with the tool's choices) for `traj` (a plan without the arm):
    the placement given, else the arm's own (`place.place`) searched with the axes
    (`place_on_axes`); the turntable's point and the track's direction as given, else the
    tool's (`resolved`)."""
    if T_base_part is not None:
        return np.asarray(T_base_part, dtype=np.float64), resolved(axes, part, T_base_part, traj)
    T0 = place(traj, robot, tcp, obstacles=obstacles).T_base_part
    return place_on_axes(traj, robot, tcp, axes, part, T0, obstacles)


__all__ = ["arm_on_axes", "overhead_tries", "place_on_axes"]
