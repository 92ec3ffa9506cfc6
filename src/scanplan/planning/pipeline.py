"""Plan a part, from its surface to one trajectory: choose the views, lay out each view's
raster, plan every pass, drop what would collide, join passes and views with clear moves.
The one module that knows views, planners and metrics together; each stage below it knows
only its own.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import ExitStack
from dataclasses import dataclass, field, replace
from functools import partial

import networkx as nx
import numpy as np

from scanplan.core.context import LOWEST, PlanContext
from scanplan.core.cover import max_cover
from scanplan.core.cycle import view_seconds
from scanplan.core.limits import TooLarge
from scanplan.core.quantities import (
    COVERAGE_TARGET,
    OVERLAP,
    UP,
    VIEW_CHOICE_CANDIDATES,
    VIEW_CHOICE_FAN_POINTS,
    ScanSpec,
)
from scanplan.core.trajectory import Trajectory
from scanplan.judging import coverage_spacing_mm, in_spec_samples
from scanplan.planning.bands import plan_adaptive_swaths
from scanplan.planning.motion import plan_transition, view_transition
from scanplan.planning.planners import Planner, pass_workers
from scanplan.planning.swaths import Swath, plan_swaths, swath_record
from scanplan.planning.view_workers import ViewJudge, ViewWorkers, view_worker_count
from scanplan.planning.views import (
    PlanView,
    View,
    ViewPlan,
    candidate_views,
    limit_beam_tilt,
    missed_views,
    plan_view,
)
from scanplan.robot.fit import fit_to_robot
from scanplan.robot.links import obstacles_for
from scanplan.world.capsule_collision import CellObstacles
from scanplan.world.cell import Cell, planned_cell
from scanplan.world.collision import checker_for
from scanplan.world.part import Part, geometry_digest
from scanplan.world.surface import (
    VisibleSurface,
    hemisphere_visible_samples,
    reachable_samples,
)

RASTERS = ("auto", "adaptive", "nominal")
# Rounds of views aimed at what the chosen views still miss (`views.missed_views`).
MISSED_ROUNDS = 4
# The least a view must add to the in-spec share to be kept, and the most views. At 1 %
# (the earlier "useful amount") the walls of small pockets, each under 1 %, got no view:
# at 0.4 % and 24 views the machined shared parts held 0.79-0.97 of their ceiling; at
# 0.1 % and 80 views the quadrotor and the pocket plate 0.90 and 0.84 against 0.86 and
# 0.83 at 0.2 % and 40 (`benchmarks/compare_views.py`; the quadrotor's thin arms take a
# view per 30° of their round, each under 0.2 %).
MIN_VIEW_GAIN = 0.001
# Below that, a view is still kept if it adds at least MIN_VIEW_GAIN_FLOOR and pays for its
# time in the cycle (`cycle.view_seconds`: its own passes and moves, and a move into it)
# with at least MIN_VIEW_GAIN_PER_S of the surface per second (0.3 % a minute). At 2e-4/s and
# 0.03 % the sheet metal part held 0.91 of its ceiling (0.90 with the full sensor); at
# 5e-5/s and 0.02 % 0.93, its cycle 160 -> 208 s (`benchmarks/compare_views.py`). A strip of
# a thin round wall (the quadrotor's propeller guards, 15° of their round a view) takes a
# second or two; a pocket's wall a few more.
MIN_VIEW_GAIN_PER_S = 5e-5
MIN_VIEW_GAIN_FLOOR = 2e-4
MAX_VIEWS = 150
# The steepest surface a top view holds much of (its passes pitch to walls of at most 60°
# along them and roll to 85° across): a part with more than 1 - COVERAGE_TARGET of its
# surface steeper needs more views.
TOP_VIEW_SLOPE_DEG = 75.0


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
            colliding = checker.check(
                planned.poses, spec.clearance_mm, colliding_only=True
            ).colliding
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
    return bool(checker.check(poses, spec.clearance_mm, colliding_only=True).colliding.all())


def _all_too_near(part: Part, spec: ScanSpec) -> str:
    return (
        f"every scanning pose on part {part.name} brings the sensor body within "
        f"{spec.clearance_mm:g} mm of the part"
    )


def order_views(plans: list[ViewPlan]) -> list[ViewPlan]:
    """The views in an order that keeps the moves between them short: the first (the top
    view) stays first, the rest follow a travelling-salesman tour (networkx's threshold
    accepting from a greedy tour, seeded) over the distance from one view's last pose to
    the next one's first (averaged both ways: the tour is symmetric)."""
    if len(plans) <= 2:
        return list(plans)
    first = np.stack([vp.traj.poses[0, :3, 3] for vp in plans])
    last = np.stack([vp.traj.poses[-1, :3, 3] for vp in plans])
    gap = np.linalg.norm(last[:, None] - first[None], axis=-1)
    graph = nx.Graph()
    for i in range(len(plans)):
        for j in range(i + 1, len(plans)):
            graph.add_edge(i, j, weight=0.5 * float(gap[i, j] + gap[j, i]))
    tour = nx.approximation.threshold_accepting_tsp(graph, "greedy", seed=0)[:-1]
    start = tour.index(0)
    order = tour[start:] + tour[:start]
    # Either direction around the tour: the one with the shorter directed moves.
    reverse = [0] + order[1:][::-1]
    cost = [sum(gap[a, b] for a, b in zip(o[:-1], o[1:], strict=True)) for o in (order, reverse)]
    return [plans[i] for i in (order if cost[0] <= cost[1] else reverse)]


@dataclass(frozen=True)
class ViewBudget:
    """How much the view choice may do: `candidates` views planned (work, the same on any
    machine), and a wall-clock limit in `seconds` only where the user asks for one."""

    candidates: int = VIEW_CHOICE_CANDIDATES
    seconds: float | None = None

    def __post_init__(self) -> None:
        if self.candidates < 1:
            raise ValueError(f"--view-candidates must be at least 1, got {self.candidates}")
        if self.seconds is not None and not (math.isfinite(self.seconds) and self.seconds > 0):
            raise ValueError(f"--view-seconds must be a number of seconds > 0, got {self.seconds}")

    def said(self) -> str:
        """How the plan's note names the budget that stopped the choice."""
        limit = f"{self.candidates} candidate views"
        return limit + (f" or {self.seconds:g} s" if self.seconds is not None else "")


@dataclass(frozen=True)
class ViewSelection:
    """The views chosen and their estimated in-spec coverage after each (`coverage`);
    `in_spec` the (k,) in-spec sets on the view choice's samples of every view planned,
    the chosen first (in order), then those left out."""

    plans: list[ViewPlan]
    coverage: list[float]
    candidates: int
    in_spec: list[np.ndarray] = field(default_factory=list)
    exact_coverage: float | None = None  # the exact cover's by as many views, for scale
    out_of_time: bool = False  # stopped by the time budget, not by gain or target


def steep_samples(part: Part, samples: VisibleSurface) -> np.ndarray:
    """(k,) bool: the `samples` on faces steeper than `TOP_VIEW_SLOPE_DEG` (their normal as
    far from ±Z: a mesh's winding does not matter here, and turning the normals outwards,
    `surface.oriented_normals`, cost the door's plan 0.3 s)."""
    normal_z = part.ray_engine.face_normals[samples.faces, 2]
    return np.abs(normal_z) < math.cos(math.radians(TOP_VIEW_SLOPE_DEG))


def top_view_may_suffice(steep: np.ndarray, coverage_target: float) -> bool:
    """False when more than 1 - `coverage_target` of the samples are `steep`
    (`steep_samples`): the top view alone cannot reach the target."""
    return bool(steep.sum() <= (1.0 - coverage_target) * len(steep))


def choose_views(
    part: Part,
    spec: ScanSpec,
    plan: PlanView,
    coverage_target: float = COVERAGE_TARGET,
    min_gain: float = MIN_VIEW_GAIN,
    max_views: int = MAX_VIEWS,
    points_per_profile: int = VIEW_CHOICE_FAN_POINTS,
    min_gain_per_s: float = MIN_VIEW_GAIN_PER_S,
    gain_floor: float = MIN_VIEW_GAIN_FLOOR,
    seed: int = 0,
    budget: ViewBudget | None = None,
    scan_level: bool = True,
    workers: int = 0,
    scheduler: str | None = None,
) -> ViewSelection:
    """Greedy set cover of the surface a sensor can see from the upper hemisphere: the top
    view first (the paper's raster; on a panel it is all there is; none if nothing to
    inspect faces up), then, while in-spec coverage is below `coverage_target`, the
    candidate view (`candidate_views`) that adds the most, unless it adds less than
    `min_gain` (`MIN_VIEW_GAIN`) and either less than `gain_floor` or less than
    `min_gain_per_s` per second of its time in the cycle (`cycle.view_seconds`); when none
    does, views
    aimed at what a beam could reach and no chosen view holds (`views.missed_views`) join
    the candidates, `MISSED_ROUNDS` times at most, each also scanned level (`View.level`,
    with `scan_level`: the direction rule left to the raster's 'auto'), none planned twice.
    A panel whose top view reaches the
    target (the door) stays one view. The exact cover by as many views among all those
    planned (`cover.max_cover`) is computed for scale (`exact_coverage`), not kept.
    Weighing a view's gain against its profiles as well (at least a quarter of the top
    view's in-spec share per profile) was tried and left out: it cost the machined parts
    1-3 points of hemisphere coverage (`benchmarks/compare_views.py`) for views that each
    add more than 1 %.

    Each view's gain is estimated by evaluating its own trajectory alone on the whole part
    with a sub-sampled fan. That is sound because a surface sample's in-spec state depends
    only on the points of one pass (the in-spec test and the density rule look at a point,
    its profile's columns and its neighbouring profiles of the same pass): the in-spec set
    of several views is the union of their in-spec sets on the same (seeded) samples, so the
    set cover is computed exactly on these sets, and a fan of 128 columns finds nearly the
    same samples (the search radius grows with the evaluated column pitch; density is judged on
    the real sensor's columns). Candidates are tried largest possible gain first (their
    region's area not yet in spec) and skipped once that bound is below the best gain found
    (lazy greedy: a view's gain only shrinks as others are chosen). Once the `budget`'s
    candidates are planned (or, only if it sets one, its seconds are past) no further
    candidate is planned: the views chosen by then are kept (`out_of_time`). With `workers`
    (`view_workers.view_worker_count`), candidates are planned on that many processes, each
    the next one the choice would try: the same views, sooner; with `scheduler`, as Dask
    tasks on that cluster."""

    budget = ViewBudget() if budget is None else budget
    deadline = None if budget.seconds is None else time.perf_counter() + budget.seconds
    timed_out = False
    taken = 0  # candidates whose plan the choice has taken: the work it counts

    def out_of_time() -> bool:
        # Asked only where another candidate would be planned: True means one was not.
        # Counted in candidates taken, not asked of the workers (how far they plan ahead
        # depends on the cores), so the same views on any machine and any load.
        nonlocal timed_out
        timed_out = timed_out or taken >= budget.candidates
        timed_out = timed_out or (deadline is not None and time.perf_counter() > deadline)
        return timed_out

    judge = ViewJudge(spec, plan, points_per_profile, seed)

    def candidates_and_faces() -> tuple[list[View], list[np.ndarray]]:
        views = candidate_views(part, spec)
        # The samples on each candidate's faces: the bound on its gain.
        return views, [np.isin(samples.faces, np.asarray(v.faces)) for v in views]

    # Asked of the workers, not yet taken: with workers, the next candidates the choice
    # would try (those not planned yet with the largest bounds), `pool.width` of them, so the
    # workers plan ahead of it. Asking for every candidate at once wasted more than it gained
    # (the heightfield's choice took 17 s against 11 in one process, which plans 7 of them).
    pending: dict[int, Future[tuple[ViewPlan, np.ndarray]]] = {}

    def ask(i: int) -> None:
        assert pool is not None
        pending[i] = pool.submit(replace(candidates[i], index=len(plans)))

    plans: list[ViewPlan] = []
    pool: ViewWorkers | None = None
    with ExitStack() as stack:
        # The top view is planned on a thread of its own from the start, beside the samples
        # the views are judged on (`evaluate` draws the same) and the workers' start: a
        # part's first samples take a few tenths of a second (the door's 0.2-0.3 s) while the
        # raster's start leaves a core free. The ray engine is built first, not by both.
        part.ray_engine  # noqa: B018
        beside = stack.enter_context(ThreadPoolExecutor(max_workers=1))
        top_view = beside.submit(judge, part, View.looking_along(UP, 0))
        samples = hemisphere_visible_samples(part, _eval_spacing(spec, points_per_profile), seed)
        steep = steep_samples(part, samples)
        if workers and scheduler is None and not top_view_may_suffice(steep, coverage_target):
            # The top view cannot be enough: the workers start now and plan, beside it, the
            # candidates with most steep surface on their faces (started after it, they held
            # the quadrotor's and the pocket plate's first candidates 1-2 s back; started
            # for the door, whose top view is enough, they cost about 0.5 s).
            candidates, on_faces = candidates_and_faces()
            pool = stack.enter_context(ViewWorkers(part, judge, workers))
            guess = [int((m & steep).sum()) for m in on_faces]
            for i in np.argsort(guess)[::-1][: pool.width]:
                ask(int(i))
        try:
            top, covered = top_view.result()
            plans, coverage, chosen = [top], [float(covered.mean())], [covered]
        except TooLarge:  # the user's numbers, not the view's fault
            raise
        except ValueError:  # nothing to inspect faces up (walls only): the views must see it all
            covered = np.zeros(len(samples.points), bool)
            plans, coverage, chosen = [], [0.0], []
        reachable: np.ndarray | None = None

        def target_reached() -> bool:
            # Of the surface, not of the visibility ceiling: the sub-sampled fan can read far
            # above the full sensor (NIST sheet metal part: 0.79 against 0.61), and a target
            # under the ceiling then stopped it at 6 views (0.61) where 16 hold 0.77.
            return coverage[-1] >= coverage_target

        if target_reached():
            return ViewSelection(plans, coverage, 0, chosen)
        if pool is None:
            # Started only now: a part whose top view is enough (the door) needs no worker, and
            # starting them anyway took the demo from 55 s to 60 beside its second process.
            candidates, on_faces = candidates_and_faces()
            pool = stack.enter_context(ViewWorkers(part, judge, workers, scheduler))
        tried = {_view_key(v) for v in candidates}
        evaluated: dict[int, tuple[ViewPlan, np.ndarray]] = {}
        rounds = 0
        least = min(min_gain, gain_floor)  # the least gain a view may be kept for
        # The move into a view: about the part's bounding radius (views are joined around it).
        entry_mm = 0.5 * float(np.linalg.norm(part.extents))
        seconds_of: dict[int, float] = {}

        def worth(gain: float, i: int) -> bool:
            if gain >= min_gain:
                return True
            if gain < gain_floor:
                return False
            if i not in seconds_of:
                seconds_of[i] = view_seconds(evaluated[i][0].traj, spec, entry_mm)
            return gain >= min_gain_per_s * seconds_of[i]

        while len(plans) < max_views and not target_reached():
            bounds = [float((m & ~covered).mean()) for m in on_faces]
            order = [int(i) for i in np.argsort(bounds)[::-1] if bounds[i] >= least]
            best: tuple[float, int] | None = None
            for rank, i in enumerate(order):
                if best is not None and bounds[i] <= best[0]:
                    break
                if i not in evaluated:
                    if i not in pending:
                        if out_of_time():
                            break
                        ask(i)
                    elif not pending[i].done() and out_of_time():
                        break
                    # From this one on: those before it were planned, or failed.
                    ahead = [j for j in order[rank:] if j not in evaluated][: pool.width]
                    for j in ahead:
                        if j not in pending and not out_of_time():
                            ask(j)
                    taken += 1
                    try:
                        evaluated[i] = pending.pop(i).result()
                    except TooLarge:  # the user's numbers, not the view's fault
                        raise
                    except ValueError:  # a view whose passes see nothing of the part
                        on_faces[i] = np.zeros_like(on_faces[i])
                        continue
                gain = float((evaluated[i][1] & ~covered).mean())
                if (best is None or gain > best[0]) and worth(gain, i):
                    best = (gain, i)
            if best is None:
                # Nothing left among the candidates: aim new ones at what is still missed.
                if rounds == MISSED_ROUNDS or out_of_time():
                    break
                rounds += 1
                if reachable is None:
                    reachable = reachable_samples(part, samples, spec.tol_angle_rad)
                more = missed_views(
                    part, spec, samples, reachable & ~covered, int(least * len(covered))
                )
                # Each also scanned level: a strip under an overhang or down a pocket is seen
                # only so (the camera beside the laser), but level costs the stepped plate and
                # the quadrotor 7 and 2 points of their ceiling when every view is scanned so.
                if scan_level:
                    more += [
                        replace(v, level=True) for v in more if v.level_direction() is not None
                    ]
                # A view planned before would add what it added then: nothing worth a view.
                more = [v for v in more if _view_key(v) not in tried]
                if not more:
                    break
                tried |= {_view_key(v) for v in more}
                candidates += more
                on_faces += [np.isin(samples.faces, np.asarray(v.faces)) for v in more]
                continue
            vp, cov = evaluated.pop(best[1])
            on_faces[best[1]] = np.zeros_like(on_faces[best[1]])
            plans.append(replace(vp, view=replace(vp.view, index=len(plans))))
            covered |= cov
            chosen.append(cov)
            coverage.append(float(covered.mean()))
    if not plans:
        raise ValueError(f"no view of part {part.name} sees its surface to inspect")
    exact = None
    if len(plans) >= 2:
        # How far greedy is from the exact cover by as many views among all those planned
        # (recorded, not used: a set without the top view first joins worse, and the
        # exact set held less on the quadrotor and the stepped plate when kept).
        try:
            _, exact = max_cover(chosen + [cov for _, cov in evaluated.values()], len(plans))
        except ValueError:  # HiGHS out of time: a figure for scale, not worth failing a plan
            exact = None
    left_out = [cov for _, cov in evaluated.values()]
    return ViewSelection(plans, coverage, len(candidates), chosen + left_out, exact, timed_out)


def _view_key(view: View) -> tuple[bytes, bytes, bool]:
    """What makes two proposed views the same view: their axis, region and scan rule."""
    faces = b"" if view.faces is None else np.sort(np.asarray(view.faces)).tobytes()
    return np.round(view.axis, 9).tobytes(), faces, view.level


def _eval_spacing(spec: ScanSpec, points_per_profile: int) -> float:
    """The sample spacing `metrics.evaluate` uses with that fan (the same samples)."""
    return coverage_spacing_mm(spec.sensor.with_points(points_per_profile))


def join_views(
    part: Part, plans: list[ViewPlan], spec: ScanSpec, cell: Cell | None = None
) -> tuple[list[ViewPlan], Trajectory]:
    """One trajectory: each view's swaths renumbered into a block of its own (view k's
    swaths follow view k−1's), joined by `view_transition`s clear of the part and its cell
    by `spec.clearance_mm`. `meta["views"]` records, per view, its axis and its swath block
    (first, last), which is how a CSV reader tells the views apart: a view is the block of
    consecutive swaths whose scanning poses look along its axis; and, where the view's plan
    carries them (`meta["swaths"]`), its pass lines (`swaths.swath_record`, view frame). A
    view no clear move reaches is left out and counted (`meta["views_unreachable"]`).
    Returns the views kept, renumbered, and the trajectory."""
    checker = checker_for(part, spec.sensor, cell)
    centre = 0.5 * (part.bounds[0] + part.bounds[1])
    # Clear of the part's bounding sphere, and no nearer than the farthest scanning pose.
    reach = max(float(np.linalg.norm(vp.traj.positions_mm - centre, axis=1).max()) for vp in plans)
    radius = max(0.5 * float(np.linalg.norm(part.extents)) + spec.clearance_mm, reach)
    pieces: list[Trajectory] = []
    views: list[dict] = []
    kept: list[ViewPlan] = []
    unreachable = 0
    first = 0
    prev_axis = plans[0].view.axis
    for vp in plans:
        traj = vp.traj
        swath = traj.swath - traj.swath.min() + first
        if pieces:
            try:
                moves = view_transition(
                    checker,
                    pieces[-1].poses[-1],
                    prev_axis,
                    traj.poses[0],
                    vp.view.axis,
                    centre,
                    radius,
                    spec.clearance_mm,
                )[:-1]  # without the next view's first pose, which its trajectory holds
            except ValueError:  # no clear way in: the scan goes on without this view
                unreachable += 1
                continue
            pieces.append(Trajectory(moves, np.full(len(moves), first), np.zeros(len(moves), bool)))
        pieces.append(replace(traj, swath=swath))
        kept.append(replace(vp, view=replace(vp.view, index=len(kept))))
        prev_axis = vp.view.axis
        record = {
            "index": len(views),
            "axis": [float(c) for c in vp.view.axis],
            "first_swath": int(swath.min()),
            "last_swath": int(swath.max()),
            "passes": vp.passes,
        }
        if lines := traj.meta.get("swaths"):
            # The pass lines (in the view's frame) numbered as the trajectory's swaths: what
            # a controller steers along when the plan is run in closed loop (`trials`).
            offset = first - int(traj.swath.min())
            record["swaths"] = [swath_record(sw, sw.index + offset) for sw in lines]
        views.append(record)
        first = int(swath.max()) + 1
    out = Trajectory.concatenate(pieces)
    meta = dict(out.meta)
    meta["views"] = views
    if unreachable:
        meta["views_unreachable"] = unreachable
    return kept, replace(out, meta=meta)


@dataclass(frozen=True)
class ViewRaster:
    """How `plan_views` plans a view (a `views.PlanView`): `plan_scan` of the part turned
    into the view's frame, in the cell turned with it; a level view (`View.level`) scanned
    level unless a direction was given. Picklable, for the view workers."""

    spec: ScanSpec
    planner: Planner
    raster: str
    direction: str
    overlap: float
    cell: Cell

    def __call__(
        self, view_part: Part, view: View, progress: Callable[[int, int], None] | None = None
    ) -> tuple[int, Trajectory]:
        level = view.level_direction() if view.level and self.direction == "auto" else None
        swaths, traj = plan_scan(
            view_part,
            self.spec,
            self.planner,
            self.raster,
            self.direction if level is None else level,
            self.overlap,
            progress,
            self.cell.rotated(view.R),
            look_first=view.faces is not None,  # a region's view, not the whole top
        )
        # The pass lines ride along to the view's record (`join_views`), for the closed loop.
        return len(swaths), replace(traj, meta=traj.meta | {"swaths": swaths})


def default_views(planner: Planner) -> str:
    """`--views` when none is given: auto for a planner that rolls (as `--raster auto`
    adapts its passes), top for the paper's pitch-only planners and a v0 policy, so the
    baselines stay the paper's single raster."""
    return "auto" if planner.roll else "top"


def plan_views(
    part: Part,
    spec: ScanSpec,
    planner: Planner,
    views: str | None = None,
    coverage_target: float = COVERAGE_TARGET,
    raster: str = "auto",
    direction: str = "auto",
    overlap: float = OVERLAP,
    roi: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    table: str = LOWEST,
    fixtures: Sequence[str] = (),
    fixture_units: str = "mm",
    arm: Arm | None = None,
    budget: ViewBudget | None = None,
    scheduler: str | None = None,
) -> tuple[list[ViewPlan], Trajectory]:
    """Plan a scan of `part` (restricted to the region of interest `roi`, the `--roi` text),
    in its cell (`cell.Cell.around`: the table and the fixture files), by views: 'top' the
    paper's single top raster, 'auto' `choose_views`, None the planner's default
    (`default_views`); each view is planned by `plan_scan` (raster, direction,
    overlap as there) on the rotated part. Returns the views and the joined trajectory
    (`join_views`), whose plan time is the whole choice's and whose `meta["context"]` records
    what it was planned under (`context.PlanContext`). progress(done, total): the top
    view's passes. With an `arm`, the plan is made flyable by it (`fit_arm`). scheduler: a
    Dask scheduler (tcp://HOST:PORT) the candidate views are planned on (None: the cores
    here; the workers import the calling script, so a script keeps its call under
    `if __name__ == "__main__":`, Python's rule for any worker process)."""
    views = default_views(planner) if views is None else views
    if scheduler is not None and views == "top":
        raise ValueError(
            "--scheduler plans the candidate views of --views auto on the cluster; this plan "
            "is the single top view"
        )
    context = PlanContext(
        spec,
        planner.limits,
        planner.name,
        views,
        roi or None,
        planner.roll,
        table,
        tuple(str(f) for f in fixtures),
        fixture_units,
        part.source,
        geometry_digest(part),
    )
    if not 0.0 < coverage_target <= 1.0:
        raise ValueError(f"--coverage-target must be in (0, 1], got {coverage_target}")
    part = part.with_roi(roi)
    cell = planned_cell(context, part)

    plan = ViewRaster(spec, planner, raster, direction, overlap, cell)

    start = time.perf_counter()
    if views == "top":
        plans = [plan_view(part, View.looking_along(UP, 0), partial(plan, progress=progress))]
    else:
        selection = choose_views(
            part,
            spec,
            plan,
            coverage_target,
            budget=budget,
            scan_level=direction == "auto",
            workers=view_worker_count(),
            scheduler=scheduler,
        )
        plans = selection.plans
    plans, traj = join_views(part, order_views(plans), spec, cell)
    traj = replace(traj, meta=traj.meta | {"context": context.to_json_dict()})
    if views != "top" and selection.out_of_time:
        budget = ViewBudget() if budget is None else budget
        traj = replace(traj, meta=traj.meta | {"view_choice_out_of_budget": budget.said()})
    if views != "top" and selection.exact_coverage is not None:
        # The view choice's own estimate (its fan, its samples) of the greedy choice, and
        # of the exact cover by as many views among those it planned.
        choice = {
            "views_planned": len(selection.in_spec),
            "in_spec_greedy": round(selection.coverage[-1], 4),
            "in_spec_exact": round(selection.exact_coverage, 4),
        }
        traj = replace(traj, meta=traj.meta | {"view_choice": choice})
    if arm is not None:
        traj = fit_arm(part, traj, arm, context)
    return plans, replace(traj, plan_time_s=time.perf_counter() - start, planner=planner.name)


@dataclass(frozen=True)
class Arm:
    """The robot a plan is made for: a preset name or file, the sensor on its flange
    (`T_flange_sensor`, mm) and the part's pose in its base frame (None: found by `place`)."""

    robot: str
    tcp: np.ndarray
    T_base_part: np.ndarray | None = None


def fit_arm(
    part: Part,
    traj: Trajectory,
    arm: Arm,
    context: PlanContext,
    obstacles: CellObstacles | None = None,
) -> Trajectory:
    """`traj` made flyable by the arm (`robot.fit.fit_to_robot`), with `meta["robot"]`: what
    it gave up, per view, and the in-spec coverage of the surface to inspect before and after
    (evaluated with the view choice's fan). obstacles: the part's cell as the links see it
    (`obstacles_for`; None: built here), for a caller that checks the fitted plan again."""
    if obstacles is None:
        spec = context.spec
        obstacles = obstacles_for(part, planned_cell(context, part), spec.sensor, spec.clearance_mm)
    fit = fit_to_robot(traj, arm.robot, arm.tcp, arm.T_base_part, obstacles=obstacles)
    record = fit.record(arm.tcp)
    for key, plan in (("in_spec_without_robot", traj), ("in_spec", fit.traj)):
        held = in_spec_samples(part, context.spec, plan, 0, VIEW_CHOICE_FAN_POINTS, context)
        record[key] = float(held.mean()) if len(held) else 0.0
    return replace(fit.traj, meta=fit.traj.meta | {"robot": record})
