"""Planners: each turns one Swath into the sensor poses of that pass.

A planner is any object with a `name`, whether it rolls the line (`roll`) and
`plan(part, swath, spec) -> Trajectory`; `plan_path` runs one over a whole Boustrophedon base
path, drops the scanning poses whose sensor body would touch the part and joins what is left
with collision-free transitions (`motion.plan_transition`); `plan_scan` also lays out that
base path.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Protocol

import numpy as np

from scanplan.part import Part
from scanplan.quantities import OVERLAP, ScanSpec
from scanplan.swaths import Swath
from scanplan.trajectory import Trajectory


class Planner(Protocol):
    """A pass planner. Two optional hooks `plan_path` looks for: `plan_passes(part, swaths,
    spec)`, every pass in one call (the closed loop steps them in lockstep), and
    `batched_passes = True`, passes planned on a thread per core (`pass_workers`)."""

    @property
    def name(self) -> str: ...

    @property
    def roll(self) -> bool:
        """Whether the planner tilts the line across the pass (beyond the paper)."""
        ...

    def plan(self, part: Part, swath: Swath, spec: ScanSpec) -> Trajectory:
        """The scanning poses of one pass (all flagged scanning, swath = swath.index)."""
        ...


def pass_workers(planner: Planner, passes: int) -> int:
    """Threads to plan passes on: one per core for a planner that measures a whole pass per
    ray cast (`batched_passes`, the geometric planner; the ray casts and much of numpy
    release the GIL), else one. (The closed loop steps all passes together instead,
    `plan_passes`.)"""
    batched = bool(getattr(planner, "batched_passes", False))
    return max(1, min(passes, os.cpu_count() or 1)) if batched else 1


PLANNERS = ("fixed", "feedback", "geometric", "rl")


RASTERS = ("auto", "adaptive", "nominal")


def make_planner(name: str, policy: str | os.PathLike | None = None, roll: bool = True) -> Planner:
    """The planner called `name`; `rl` loads a policy directory (None: the shipped one) and
    rolls if the policy is a v1 one. roll=False: the paper's pitch-only geometric and
    feedback planners."""
    if name == "fixed":
        from scanplan.planners.fixed import FixedPlanner

        return FixedPlanner()
    if name == "feedback":
        from scanplan.planners.feedback import FeedbackPlanner

        return FeedbackPlanner(roll=roll)
    if name == "geometric":
        from scanplan.planners.geometric import GeometricPlanner

        return GeometricPlanner.with_roll() if roll else GeometricPlanner()
    if name == "rl":
        from scanplan.planners.rl import RLPlanner

        return RLPlanner.from_file(None if policy is None else Path(policy))
    raise ValueError(f"unknown planner {name!r}; use one of {', '.join(PLANNERS)}")


def plan_path(
    part: Part,
    spec: ScanSpec,
    planner: Planner,
    swaths: list[Swath],
    progress: Callable[[int, int], None] | None = None,
) -> Trajectory:
    """All passes in snake order, joined by non-scanning transitions that keep the sensor
    body `spec.clearance_mm` from the part (SPEC §3b).

    A scanning pose whose body would come closer than the clearance is not emitted: the pass
    is cut there and its pieces are joined like passes (lift over, descend).
    meta["collisions_dropped"] counts the dropped poses. progress(done, total) is called
    after each pass (a caller's progress bar).
    """
    from scanplan.collision import checker_for
    from scanplan.motion import plan_transition

    if not swaths:
        raise ValueError("no swath to plan")
    start = time.perf_counter()
    checker = checker_for(part, spec.sensor)
    pieces: list[Trajectory] = []
    dropped = 0
    last_pose: np.ndarray | None = None
    # Passes are independent: planned all in one call by a planner that steps them together
    # (`plan_passes`, the closed loop), else on `pass_workers` threads; taken in order.
    plan_passes = getattr(planner, "plan_passes", None)
    pool = ThreadPoolExecutor(max_workers=pass_workers(planner, len(swaths)))
    try:
        if plan_passes is not None:
            jobs = [_done(t) for t in plan_passes(part, swaths, spec)]
        else:
            jobs = [pool.submit(planner.plan, part, swath, spec) for swath in swaths]
        for i, (swath, job) in enumerate(zip(swaths, jobs, strict=True)):
            planned = job.result()
            colliding = checker.check(planned.poses, spec.clearance_mm).colliding
            dropped += int(colliding.sum())
            for k, run in enumerate(_runs(~colliding)):
                poses = planned.poses[run]
                if last_pose is not None:
                    moves = plan_transition(checker, last_pose, poses[0], spec.clearance_mm)
                    pieces.append(
                        Trajectory(
                            moves, np.full(len(moves), swath.index), np.zeros(len(moves), bool)
                        )
                    )
                pieces.append(
                    Trajectory(
                        poses,
                        planned.swath[run],
                        planned.scanning[run],
                        meta=planned.meta if k == 0 else {},  # the pass's counters once
                    )
                )
                last_pose = poses[-1]
            if progress is not None:
                progress(i + 1, len(swaths))
    finally:
        pool.shutdown(cancel_futures=True)
    if not pieces:
        raise ValueError(
            f"every scanning pose on part {part.name} brings the sensor body within "
            f"{spec.clearance_mm:g} mm of the part"
        )
    traj = Trajectory.concatenate(pieces, planner=planner.name)
    return Trajectory(
        traj.poses,
        traj.swath,
        traj.scanning,
        plan_time_s=time.perf_counter() - start,
        planner=planner.name,
        meta={**traj.meta, "collisions_dropped": dropped},
    )


def _done(result: Trajectory) -> Future[Trajectory]:
    """A future that already holds `result`."""
    future: Future[Trajectory] = Future()
    future.set_result(result)
    return future


def _runs(keep: np.ndarray) -> list[slice]:
    """The maximal runs of True in `keep`, as slices."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], keep.astype(np.int8), [0]])))
    return [slice(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def plan_scan(
    part: Part,
    spec: ScanSpec,
    planner: Planner,
    raster: str = "auto",
    direction: str = "auto",
    overlap: float = OVERLAP,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[list[Swath], Trajectory]:
    """The base path and the planned trajectory. raster: 'nominal' is the paper's (lateral
    step = line width x (1 − overlap)); 'adaptive' spaces passes by the band of the line that
    stays in spec (SPEC §3b) — it assumes the line rolls with the surface; 'auto' takes
    adaptive for a planner that rolls, else nominal."""
    from scanplan.swaths import plan_adaptive_swaths, plan_swaths

    if raster not in RASTERS:
        raise ValueError(f"unknown raster {raster!r}; use one of {', '.join(RASTERS)}")
    if raster == "adaptive" or (raster == "auto" and planner.roll):
        swaths = plan_adaptive_swaths(part, spec, direction)
    else:
        swaths = plan_swaths(part, spec.sensor, direction, overlap)
    return swaths, plan_path(part, spec, planner, swaths, progress)
