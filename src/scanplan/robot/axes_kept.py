"""What a placed arm keeps of a plan's views at settings of its external axes (`axes`):
each setting's values along the poses (`values_at`), and the scanning poses kept at each
setting of each view, judged together (`kept_each`: a copy of a view's poses per setting,
each followed as a path of its own), or bounded from above by the inverse kinematics alone
(`reach_bound_each`), which the placement search ranks its stands by before judging them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from scanplan.core.trajectory import Trajectory
from scanplan.robot.axes import ExternalAxes, part_poses
from scanplan.robot.base import Robot
from scanplan.robot.flown_poses import (
    flyable_poses,
    kept_by_pass,
    sensor_clear_both,
)
from scanplan.world.capsule_collision import CellObstacles

# Poses (a copy per setting) judged in one reach check: about 100 MB of inverse kinematics.
JUDGED_TOGETHER = 60_000


def values_at(
    axes: ExternalAxes,
    setting: np.ndarray,
    T_base_part: np.ndarray,
    poses: np.ndarray,
    inv_tcp: np.ndarray,
) -> np.ndarray:
    """(n, k) the axes' values at `poses` (part frame) for a `setting` (k,): the turntable's
    angle as it is; the track at s = d·flange - offset (the flange's along-track position
    at the turntable's angle), clipped to its travel."""
    values = np.tile(np.asarray(setting, dtype=np.float64), (len(poses), 1))
    if axes.track is not None:
        assert axes.track.direction is not None
        d = np.asarray(axes.track.direction, dtype=np.float64)
        d = d / np.linalg.norm(d)
        at = values.copy()
        at[:, -1] = 0.0
        flange = (part_poses(T_base_part, at, axes) @ poses @ inv_tcp)[:, :3, 3]
        lo, hi = axes.limits[-1]
        values[:, -1] = np.clip(flange @ d - setting[-1], lo, hi)
    return values


def kept_each(
    traj: Trajectory,
    arm: Robot,
    T_base_part: np.ndarray,
    inv_tcp: np.ndarray,
    obstacles: CellObstacles | None,
    axes: ExternalAxes,
    jobs: Sequence[tuple[np.ndarray, np.ndarray]],
) -> list[np.ndarray]:
    """For each job (settings (c, k), index), (c,) the scanning poses among `index` kept at
    each setting (each pass as planned or turned half a turn, as the fit keeps them). The
    jobs' settings are judged together, a copy of a job's poses per setting followed as a
    path of its own (`check_reach`'s restarts), about `JUDGED_TOGETHER` poses a call: the
    same counts as a call per setting, without the cost of a call on a view's few poses
    each time."""

    def judged(copies: _Copies) -> np.ndarray:
        if obstacles is None:
            good = list(flyable_poses(copies.traj, arm, copies.T, inv_tcp, None))  # reach alone
        else:
            # The sensor's clearance does not depend on the setting: judged once a pose.
            poses, at = np.unique(copies.source, return_inverse=True)
            clear = sensor_clear_both(traj.poses[poses], obstacles)
            good = list(
                flyable_poses(
                    copies.traj,
                    arm,
                    copies.T,
                    inv_tcp,
                    obstacles,
                    sensor_ok=(clear[0][at], clear[1][at]),
                    exact=False,
                    choosing=np.ones(len(copies.traj), bool),
                    restarts=copies.restarts,
                )
            )
        kept = kept_by_pass(copies.traj.swath, good[0], good[1]) & copies.traj.scanning
        return np.bincount(copies.copy_of, kept, copies.count)

    return _in_batches(traj, T_base_part, inv_tcp, axes, jobs, judged)


def reach_bound_each(
    traj: Trajectory,
    arm: Robot,
    T_base_part: np.ndarray,
    inv_tcp: np.ndarray,
    axes: ExternalAxes,
    jobs: Sequence[tuple[np.ndarray, np.ndarray]],
) -> list[np.ndarray]:
    """For each job (settings, index), (c,) at least what `kept_each` keeps without
    obstacles at each setting: per pass, the larger of its poses with an inverse kinematics
    solution within the joint limits as planned and as turned half a turn (the reach check
    keeps no pose without one, and a pass one way)."""

    def bound(copies: _Copies) -> np.ndarray:
        reached = flyable_poses(copies.traj, arm, copies.T, inv_tcp, None)  # reach alone
        held = [r & copies.traj.scanning for r in reached]
        passes, first, at = np.unique(copies.traj.swath, return_index=True, return_inverse=True)
        most = np.maximum(
            np.bincount(at, held[0], len(passes)), np.bincount(at, held[1], len(passes))
        )
        return np.bincount(copies.copy_of[first], most, copies.count)

    return _in_batches(traj, T_base_part, inv_tcp, axes, jobs, bound)


@dataclass(frozen=True)
class _Copies:
    """Jobs' poses copied once per setting, each copy's passes its own: the copies (`traj`),
    the part's pose at each (n, 4, 4), where each copy starts (`restarts`), the copy each
    pose is of (`copy_of`, of `count`) and the pose of the plan it copies (`source`)."""

    traj: Trajectory
    T: np.ndarray
    restarts: np.ndarray
    copy_of: np.ndarray
    count: int
    source: np.ndarray


def _in_batches(
    traj: Trajectory,
    T_base_part: np.ndarray,
    inv_tcp: np.ndarray,
    axes: ExternalAxes,
    jobs: Sequence[tuple[np.ndarray, np.ndarray]],
    judge: Callable[[_Copies], np.ndarray],
) -> list[np.ndarray]:
    """Each job's (c,) figures: `judge` of the copies of about `JUDGED_TOGETHER` poses at a
    time (its figure per copy), split per job."""
    per_copy: list[np.ndarray] = []
    batch: list[tuple[np.ndarray, np.ndarray]] = []
    size = 0
    for k, (settings, index) in enumerate(jobs):
        batch.append((settings, index))
        size += len(settings) * len(index)
        if size >= JUDGED_TOGETHER or k == len(jobs) - 1:
            copies = _copies(traj, T_base_part, inv_tcp, axes, batch)
            figures = judge(copies) if len(copies.traj) else np.zeros(copies.count)
            per_copy.append(np.asarray(figures, dtype=np.float64))
            batch, size = [], 0
    flat = np.concatenate(per_copy) if per_copy else np.zeros(0)
    ends = np.cumsum([len(settings) for settings, _ in jobs])
    return np.split(flat, ends[:-1]) if len(jobs) else []


def _copies(
    traj: Trajectory,
    T_base_part: np.ndarray,
    inv_tcp: np.ndarray,
    axes: ExternalAxes,
    jobs: Sequence[tuple[np.ndarray, np.ndarray]],
) -> _Copies:
    """The `_Copies` of `jobs` (settings, index)."""
    poses, swaths, source, values, copy_of = [], [], [], [], []
    shift, count = 0, 0
    for settings, index in jobs:
        index = np.flatnonzero(np.isin(np.arange(len(traj)), index))  # in the plan's order
        m, c = len(index), len(settings)
        swath = traj.swath[index] - (traj.swath[index].min() if m else 0)
        span = int(swath.max()) + 1 if m else 0
        poses.append(np.tile(traj.poses[index], (c, 1, 1)))
        swaths.append(np.tile(swath, c) + shift + np.repeat(np.arange(c) * span, m))
        source.append(np.tile(index, c))
        copy_of.append(np.repeat(count + np.arange(c), m))
        values += [values_at(axes, s, T_base_part, traj.poses[index], inv_tcp) for s in settings]
        shift, count = shift + c * span, count + c
    src = np.concatenate(source).astype(np.int64)
    copies = Trajectory(
        np.concatenate(poses).reshape(-1, 4, 4),
        np.concatenate(swaths).astype(np.int64),
        traj.scanning[src],
    )
    of = np.concatenate(copy_of).astype(np.int64)
    restarts = np.r_[True, of[1:] != of[:-1]] if len(of) else np.zeros(0, bool)
    n = len(src)
    T = (
        part_poses(T_base_part, np.concatenate(values).reshape(n, -1), axes)
        if n
        else np.zeros((0, 4, 4))
    )
    return _Copies(copies, T, restarts, of, count, src)


__all__ = ["JUDGED_TOGETHER", "kept_each", "reach_bound_each", "values_at"]
