"""One view's passes planned into one path: its raster laid out (nominal or adaptive), each
pass planned, what would collide or cannot be reached dropped, the pieces joined by clear
moves. `ViewRaster` is how a view (a part turned into its frame) is planned so.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from scanplan.core.quantities import OVERLAP, UP, ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.planning.bands import plan_adaptive_swaths
from scanplan.planning.motion import plan_transition
from scanplan.planning.planners import Planner, pass_workers
from scanplan.planning.swaths import Swath, plan_swaths
from scanplan.planning.view_poses import limit_beam_tilt
from scanplan.planning.views import View
from scanplan.world.cell import Cell
from scanplan.world.collision import checker_for
from scanplan.world.part import Part

RASTERS = ("auto", "adaptive", "nominal")


def plan_path(
    part: Part,
    spec: ScanSpec,
    planner: Planner,
    swaths: list[Swath],
    progress: Callable[[int, int], None] | None = None,
    cell: Cell | None = None,
) -> Trajectory:
    """All passes in snake order, joined by non-scanning transitions that keep the sensor
    body `spec.clearance_mm` from the part and its `cell` (table, fixtures; None: nothing
    around the part).

    A scanning pose whose body would come closer than the clearance is not emitted: the pass
    is cut there and its pieces are joined like passes (lift over, descend; along the
    table's normal where lifting along +Z finds no clear way, a view tilted towards a wall).
    A piece no clear move reaches is given up. meta["collisions_dropped"] and
    meta["unreachable_dropped"] count the scanning poses dropped each way.
    progress(done, total) is called after each pass (a caller's progress bar).
    """
    if not swaths:
        raise ValueError("no swath to plan")
    start = time.perf_counter()
    checker = checker_for(part, spec.sensor, cell)
    pieces: list[Trajectory] = []
    dropped = unreachable = 0
    last_pose: np.ndarray | None = None
    # The table's up in this frame: in a view tilted towards a wall, lifting along the
    # view's axis runs along the table, lifting away from the table clears it.
    uphill = None if cell is None or cell.table is None else cell.table.normal
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
            if cell is not None and cell.table is not None:
                planned = replace(
                    planned,
                    poses=limit_beam_tilt(
                        planned.poses, cell.table.normal, spec.working_distance_mm
                    ),
                )
            colliding = checker.colliding(planned.poses, spec.clearance_mm)
            dropped += int(colliding.sum())
            for k, run in enumerate(_runs(~colliding)):
                poses = planned.poses[run]
                if last_pose is not None:
                    moves = _move(checker, last_pose, poses[0], spec.clearance_mm, uphill)
                    if moves is None:  # no clear way there: this piece is given up
                        unreachable += len(poses)
                        continue
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
        raise ValueError(_all_too_near(part, spec))
    traj = Trajectory.concatenate(pieces, planner=planner.name)
    return Trajectory(
        traj.poses,
        traj.swath,
        traj.scanning,
        plan_time_s=time.perf_counter() - start,
        planner=planner.name,
        meta={
            **traj.meta,
            "collisions_dropped": dropped,
            **({"unreachable_dropped": unreachable} if unreachable else {}),
        },
    )


def _move(
    checker, start: np.ndarray, end: np.ndarray, clearance_mm: float, uphill: np.ndarray | None
) -> np.ndarray | None:
    """A clear move from `start` to `end` (`motion.plan_transition`): lifting along this
    frame's +Z, else along the table's `uphill` normal; None if neither is clear."""
    for up in (UP, uphill):
        if up is None:
            continue
        try:
            return plan_transition(checker, start, end, clearance_mm, up=up)
        except ValueError:
            continue
    return None


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
    direction: str | np.ndarray = "auto",
    overlap: float = OVERLAP,
    progress: Callable[[int, int], None] | None = None,
    cell: Cell | None = None,
    look_first: bool = False,
) -> tuple[list[Swath], Trajectory]:
    """The base path and the planned trajectory. raster: 'nominal' is the paper's (lateral
    step = line width x (1 − overlap)); 'adaptive' spaces passes by the band of the line that
    stays in spec (SPEC §3b) — it assumes the line rolls with the surface; 'auto' takes
    adaptive for a planner that rolls, else nominal. direction: a rule (`swaths.direction_rule`)
    or a scan direction in the part's frame. look_first: give up before planning, with
    `plan_path`'s error, when the sensor body at every pass's level poses
    (`passes_blocked`) is already too near the part or its cell."""
    if raster not in RASTERS:
        raise ValueError(f"unknown raster {raster!r}; use one of {', '.join(RASTERS)}")
    uphill = None if cell is None or cell.table is None else cell.table.normal
    if raster == "adaptive" or (raster == "auto" and planner.roll):
        swaths = plan_adaptive_swaths(part, spec, direction, uphill=uphill)
    else:
        swaths = plan_swaths(part, spec.sensor, direction, overlap, uphill=uphill)
    if look_first and passes_blocked(part, spec, swaths, cell):
        raise ValueError(_all_too_near(part, spec))
    return swaths, plan_path(part, spec, planner, swaths, progress, cell)


# Level poses looked at per pass by `passes_blocked`.
LOOK_POSES_PER_PASS = 9


def passes_blocked(part: Part, spec: ScanSpec, swaths: list[Swath], cell: Cell | None) -> bool:
    """Whether the sensor body comes within `spec.clearance_mm` of the part or its cell at
    every one of `LOOK_POSES_PER_PASS` level poses along each pass (at the pass's height,
    looking straight down): a view of a wall seen past another part of the part, which the
    planner would plan only for every pose to be dropped (106 of the quadrotor's 345 views
    planned; 136 of the 138 such views on five shared parts were planned to nothing)."""
    n = LOOK_POSES_PER_PASS
    poses = np.concatenate(
        [
            sw.poses(np.linspace(0.0, max(sw.length_mm, 0.0), n), np.zeros(n), np.zeros(n))
            for sw in swaths
        ]
    )
    checker = checker_for(part, spec.sensor, cell)
    return bool(checker.colliding(poses, spec.clearance_mm).all())


def _all_too_near(part: Part, spec: ScanSpec) -> str:
    return (
        f"every scanning pose on part {part.name} brings the sensor body within "
        f"{spec.clearance_mm:g} mm of the part"
    )


@dataclass(frozen=True)
class ViewRaster:
    """How `plan_views` plans a view (a `views.PlanView`): `plan_scan` of the part turned
    into the view's frame, in the cell turned with it; a view scanned level or up its tilt
    (`View.scan_direction`) so unless a direction was given. Picklable, for the view workers."""

    spec: ScanSpec
    planner: Planner
    raster: str
    direction: str
    overlap: float
    cell: Cell

    def __call__(
        self, view_part: Part, view: View, progress: Callable[[int, int], None] | None = None
    ) -> tuple[int, Trajectory]:
        scan = view.scan_direction() if self.direction == "auto" else None
        swaths, traj = plan_scan(
            view_part,
            self.spec,
            self.planner,
            self.raster,
            self.direction if scan is None else scan,
            self.overlap,
            progress,
            self.cell.rotated(view.R),
            look_first=view.faces is not None,  # a region's view, not the whole top
        )
        # The pass lines ride along to the view's record (`join_views`), for the closed loop.
        return len(swaths), replace(traj, meta=traj.meta | {"swaths": swaths})
