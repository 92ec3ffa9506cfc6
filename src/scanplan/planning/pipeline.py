"""Plan a part, from its surface to one trajectory: choose the views (`view_choice`), plan
each view's passes (`pass_path`), join the views with clear moves (`view_joining`), and fit
the plan to an arm. The one module that knows views, planners and metrics together.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable, Sequence
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from scanplan.core.context import LOWEST, PlanContext
from scanplan.core.plan import ViewRecord, view_records
from scanplan.core.quantities import COVERAGE_TARGET, OVERLAP, UP, VIEW_CHOICE_FAN_POINTS, ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.judging import in_spec_samples
from scanplan.planning.pass_path import ViewRaster
from scanplan.planning.planners import Planner
from scanplan.planning.view_budget import ViewBudget
from scanplan.planning.view_choice import ViewSelection, choose_views
from scanplan.planning.view_joining import join_views, order_views
from scanplan.planning.view_workers import process_beside, view_worker_count
from scanplan.planning.views import View, ViewPlan, plan_view
from scanplan.robot.axes import ExternalAxes, with_disk
from scanplan.robot.axes_fit import PlacedArmOnAxes, choose_values, fitted_axes_record
from scanplan.robot.axes_place import arm_on_axes
from scanplan.robot.base import pose_arg
from scanplan.robot.fit import CAUSES, RobotFit, beyond_reach_mm, fit_to_robot
from scanplan.robot.links import obstacles_for, where_it_stands
from scanplan.robot.place import best_placement
from scanplan.robot.place_weights import pose_weights, view_worths
from scanplan.robot.placed_arm import PlacedArm
from scanplan.robot.presets import get_robot
from scanplan.robot.reach import check_reach
from scanplan.world.capsule_collision import CellObstacles
from scanplan.world.cell import Cell, planned_cell
from scanplan.world.part import Part, geometry_digest


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
    (`default_views`); each view is planned by `pass_path.plan_scan` (raster, direction,
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
    # Planned among its fixtures: they hide the part from every probe, view and judgement.
    part = cell.occluding(part)

    plan = ViewRaster(spec, planner, raster, direction, overlap, cell)

    start = time.perf_counter()
    brackets: list[dict] = []
    obstacles = None if arm is None else obstacles_for(part, cell, spec.sensor, spec.clearance_mm)
    free: Trajectory | None = None
    free_views: list[tuple[ViewPlan, np.ndarray]] | None = None  # chosen without the arm
    if views == "top":
        plans = [plan_view(part, View.looking_along(UP, 0), partial(plan, progress=progress))]
    else:
        choose = partial(
            choose_views,
            part,
            spec,
            plan,
            coverage_target,
            budget=budget,
            scan_level=direction == "auto",
            workers=view_worker_count(),
            scheduler=scheduler,
        )
        placed, known = None, None
        listed: tuple[View, ...] = ()  # the candidates the choice without the arm listed
        if arm is not None:
            # Views chosen for the arm: placed where it flies most of what the views chosen
            # without it hold, then each candidate judged by what the arm flies of it there
            # (those the free choice planned are not planned again).
            first = choose()
            known, listed = first.known, first.listed
            free, free_views, weights = _free_plan(part, first, spec, cell)
            arm, brackets = _placed(part, free, arm, context, obstacles, weights)
            placed = _placed_arm(arm, context, part, obstacles)
        selection = choose(arm=placed, known=known, listed=listed)
        plans = selection.plans
    plans, traj = join_views(part, order_views(plans), spec, cell)
    traj = replace(traj, meta=traj.meta | {"context": context.to_json_dict()})
    if views != "top":
        traj = _with_choice(traj, selection, budget)
    if arm is not None:
        traj = fit_arm(part, traj, arm, context, obstacles, free, free_views)
        if brackets:
            record = traj.meta["robot"] | {"brackets": brackets}
            traj = replace(traj, meta=traj.meta | {"robot": record})
    return plans, replace(traj, plan_time_s=time.perf_counter() - start, planner=planner.name)


def _with_choice(
    traj: Trajectory, selection: ViewSelection, budget: ViewBudget | None
) -> Trajectory:
    """`traj` with what its view choice records: whether its budget stopped it (and the
    budget), and its own estimate of the cover (`_choice_record`)."""
    if selection.out_of_time:
        budget = ViewBudget() if budget is None else budget
        traj = replace(traj, meta=traj.meta | {"view_choice_out_of_budget": budget.said()})
    if selection.exact_coverage is not None:
        traj = replace(traj, meta=traj.meta | {"view_choice": _choice_record(selection)})
    return traj


def _choice_record(selection: ViewSelection) -> dict:
    """The view choice's own estimate (its fan, its samples) of the greedy choice, and of
    the exact cover by as many views among those it planned."""
    assert selection.exact_coverage is not None
    return {
        "views_planned": len(selection.in_spec),
        "in_spec_greedy": round(selection.coverage[-1], 4),
        "in_spec_exact": round(selection.exact_coverage, 4),
    }


@dataclass(frozen=True)
class Arm:
    """The robot a plan is made for: a preset name or file, the sensor on its flange
    (`T_flange_sensor`, mm) and the part's pose in its base frame (None: found by `place`);
    the cell's external axes (a turntable, a track; `robot.axes`), None: the arm alone.
    `brackets`: several sensor mounts to choose `tcp` among (`_placed`), if given."""

    robot: str
    tcp: np.ndarray
    T_base_part: np.ndarray | None = None
    axes: ExternalAxes | None = None
    brackets: tuple[np.ndarray, ...] = ()


def _placed_arm(
    arm: Arm, context: PlanContext, part: Part, obstacles: CellObstacles | None
) -> PlacedArm:
    """The placed `arm` as the view choice flies a candidate with it; without axes, judging
    `part` among the `obstacles` built already, if given (with axes: their disk too)."""
    assert arm.T_base_part is not None
    if arm.axes is not None:
        return PlacedArmOnAxes(arm.robot, arm.tcp, arm.T_base_part, context, arm.axes)
    placed = PlacedArm(arm.robot, arm.tcp, arm.T_base_part, context)
    return placed if obstacles is None else placed.among(part, obstacles)


def _free_plan(
    part: Part, first: ViewSelection, spec: ScanSpec, cell: Cell
) -> tuple[Trajectory, list[tuple[ViewPlan, np.ndarray]], np.ndarray]:
    """The plan chosen without the arm (`first`) joined; its views, each with its in-spec
    set; and what each of its poses is worth to the arm's placement: its view's share of
    the surface in spec, what it shares with other views split among them (`view_worths`),
    so a view holding surface no other holds outweighs one of many poses holding what
    others hold too."""
    free_views = list(zip(first.plans, first.in_spec, strict=False))  # chosen first
    joined, free = join_views(part, order_views(first.plans), spec, cell)
    held_by = {id(vp.traj): cov for vp, cov in free_views}  # `join_views` keeps each traj
    worths = view_worths([held_by[id(vp.traj)] for vp in joined])
    return free, free_views, pose_weights(free, worths)


def _placed(
    part: Part,
    free: Trajectory,
    arm: Arm,
    context: PlanContext,
    obstacles: CellObstacles | None,
    weights: np.ndarray | None = None,
) -> tuple[Arm, list[dict]]:
    """`arm` placed (by `place`, its poses worth `weights`, or with its axes by
    `arm_on_axes`, unless it is) for the plan made without it (`free`); with several
    `brackets`, each placed and judged by the in-spec coverage the arm flies of `free`
    from there (`PlacedArm.flown`, the view choice's fan), the best kept. Returns the arm
    and, with brackets, what each flew (`tcp`, `part_pose`, `in_spec_flown`)."""
    tried: list[tuple[float, Arm]] = []
    brackets: list[dict] = []
    for tcp in arm.brackets or (arm.tcp,):
        T_base_part = arm.T_base_part
        if arm.axes is not None:
            T_base_part, axes = arm_on_axes(
                free, arm.robot, tcp, T_base_part, arm.axes, part, obstacles
            )
            candidate = replace(arm, tcp=tcp, T_base_part=T_base_part, axes=axes)
        else:
            if T_base_part is None:
                # Placed only: `fit_arm` checks the plan chosen for the arm there, not this.
                T_base_part, *_ = best_placement(
                    free, get_robot(arm.robot), tcp, obstacles=obstacles, weights=weights
                )
            candidate = replace(arm, tcp=tcp, T_base_part=T_base_part)
        if len(arm.brackets) < 2:
            return candidate, []
        flown = _placed_arm(candidate, context, part, obstacles).flown(part, free)
        try:
            share = _held_share(part, flown, context)
        except ValueError:  # the arm flies nothing that measures
            share = 0.0
        tried.append((share, candidate))
        brackets.append(
            {
                "tcp": pose_arg(tcp),
                "part_pose": pose_arg(T_base_part),
                "in_spec_flown": round(share, 4),
            }
        )
    best = max(range(len(tried)), key=lambda k: tried[k][0])  # the first of equals
    for k, said in enumerate(brackets):
        said["used"] = k == best
    return tried[best][1], brackets


def fit_arm(
    part: Part,
    traj: Trajectory,
    arm: Arm,
    context: PlanContext,
    obstacles: CellObstacles | None = None,
    free: Trajectory | None = None,
    free_views: list[tuple[ViewPlan, np.ndarray]] | None = None,
) -> Trajectory:
    """`traj` made flyable by the arm (`robot.fit.fit_to_robot`), with `meta["robot"]`: what
    it gave up, per view, and the in-spec coverage of the surface to inspect before and after
    (evaluated with the view choice's fan), and of the plan made without the arm (`free`),
    if one was. obstacles: the part's cell as the links see it (`obstacles_for`; None:
    built here), for a caller that checks the fitted plan again. free_views: the views that
    plan was chosen from, each with its in-spec set on the view choice's samples: those the
    fitted plan misses are recorded with why (`_not_flown`), for an arm without axes."""
    if obstacles is None:
        spec = context.spec
        obstacles = obstacles_for(part, planned_cell(context, part), spec.sensor, spec.clearance_mm)
    if arm.axes is not None:  # the axes' settings chosen view by view (`robot.axes_fit`)
        if arm.T_base_part is None or not arm.axes.resolved:
            T0, axes = arm_on_axes(
                traj, arm.robot, arm.tcp, arm.T_base_part, arm.axes, part, obstacles
            )
            arm = replace(arm, T_base_part=T0, axes=axes)
        assert arm.T_base_part is not None and arm.axes is not None
        spec = context.spec
        cell = with_disk(planned_cell(context, part), arm.axes)
        obstacles = obstacles_for(part, cell, spec.sensor, spec.clearance_mm)
        centre = part.bounds.mean(axis=0)
        traj, _ = choose_values(
            traj, arm.robot, arm.tcp, arm.T_base_part, arm.axes, obstacles, centre
        )
    with process_beside() as beside:
        # The views as planned and the plan without the arm are judged on the other core
        # while this one fits the arm: neither depends on the fit.
        ahead = (part, traj, context, free)
        judging = None if beside is None else beside.submit(_judged_unfitted, *ahead)
        fit = fit_to_robot(
            traj, arm.robot, arm.tcp, arm.T_base_part, obstacles=obstacles, axes=arm.axes
        )
        try:
            unfitted = _judged_unfitted(*ahead) if judging is None else judging.result()
        except BrokenProcessPool:  # the process died (killed, out of memory): judged here
            unfitted = _judged_unfitted(*ahead)
    planned, judged, free_share = unfitted
    record = fit.record(arm.tcp)
    if arm.axes is None and (stands := where_it_stands(fit.T_base_part, obstacles.table_block)):
        record["stands"] = stands
    if arm.axes is not None:
        record["external_axes"] = fitted_axes_record(arm.axes, fit.traj)
    # Judged view by view (a sample's in-spec state depends on one pass): the union is the
    # plan's figure, and what a view held that nothing flown holds is what the arm cost. A
    # view the fit left alone is not measured again (`judged`).
    flown = _held_by_view(part, fit.traj, context, judged)
    sets = [*planned.values(), *flown.values()]
    nothing = np.zeros(len(sets[0]) if sets else 0, bool)
    held = np.logical_or.reduce([nothing, *flown.values()])
    before = np.logical_or.reduce([nothing, *planned.values()])
    record["in_spec"] = float(held.mean()) if len(held) else 0.0
    record["in_spec_without_robot"] = float(before.mean()) if len(before) else 0.0
    record["in_spec_lost_by_view"] = {
        str(k): round(float((v & ~held).mean()), 4)
        for k, v in planned.items()
        if (v & ~held).mean() >= 5e-4
    }
    if free_views and arm.axes is None:
        views, share = _not_flown(free_views, held, arm.robot, arm.tcp, fit)
        record["free_views_not_flown"] = views
        record["in_spec_not_flown"] = share
    if free_share is not None:
        record["in_spec_free_plan"] = free_share
    return replace(fit.traj, meta=fit.traj.meta | {"robot": record})


def _judged_unfitted(
    part: Part, traj: Trajectory, context: PlanContext, free: Trajectory | None
) -> tuple[dict[int, np.ndarray], dict[bytes, np.ndarray | None], float | None]:
    """What `fit_arm` judges of the plan before the fit: each view's in-spec set as planned,
    the sets by view key (`_held_by_view`'s `judged`), and the share the plan made without
    the arm (`free`, if any) holds. Run in a process beside the fit (picklable both ways)."""
    judged: dict[bytes, np.ndarray | None] = {}
    planned = _held_by_view(part, traj, context, judged)
    return planned, judged, None if free is None else _held_share(part, free, context)


def _held_share(part: Part, traj: Trajectory, context: PlanContext) -> float:
    """The share of the view choice's samples `traj` holds in spec (`in_spec_samples`)."""
    held = in_spec_samples(part, context.spec, traj, 0, VIEW_CHOICE_FAN_POINTS, context)
    return float(held.mean()) if len(held) else 0.0


def _held_by_view(
    part: Part, traj: Trajectory, context: PlanContext, judged: dict[bytes, np.ndarray | None]
) -> dict[int, np.ndarray]:
    """Each view's in-spec set on the view choice's samples (`in_spec_samples`); none for a
    view that measures nothing. `judged`: the sets found so far, by the view's poses and
    passes (what `in_spec_samples` depends on; None: it measures nothing), added to."""
    out = {}
    for view in view_records(traj) or (ViewRecord(0, (0.0, 0.0, 1.0), 0, 1 << 30, 0),):
        mine = view.holds(traj.swath)
        if not (mine & traj.scanning).any():
            continue
        sub = traj.subset(mine)
        passes = np.r_[True, sub.swath[1:] != sub.swath[:-1]]
        what = (sub.poses, sub.scanning, passes)  # what its in-spec set depends on
        key = hashlib.sha256(b"".join(a.tobytes() for a in what)).digest()
        if key not in judged:
            try:
                judged[key] = in_spec_samples(
                    part, context.spec, sub, 0, VIEW_CHOICE_FAN_POINTS, context
                )
            except ValueError:  # what the arm left of a view measures nothing: it holds nothing
                judged[key] = None
        if (held := judged[key]) is not None:
            out[view.index] = held
    return out


# A view of the plan without the arm whose surface the arm's plan misses less of than this
# share is not said (a few samples either way).
NOT_FLOWN_LEAST = 0.005


def _not_flown(
    free_views: list[tuple[ViewPlan, np.ndarray]],
    held: np.ndarray,
    robot: str,
    tcp: np.ndarray,
    fit: RobotFit,
) -> tuple[list[dict], float]:
    """The views of the plan made without the arm (each with its in-spec set on the view
    choice's samples) whose surface the arm's plan (in spec on `held`) misses, largest
    first: the view's axis, the share it misses, and why the arm at its placement cannot
    fly its scanning poses (out of reach, the farthest how far beyond the arm's horizontal
    reach; beyond the joint limits). The views the arm flies are chosen for it; these are
    what no view it can fly holds from where it stands. Returns them, and the share of the
    surface they hold and the arm's plan does not."""
    arm = get_robot(robot)
    inv_tcp = np.linalg.inv(tcp)
    out = []
    missed = np.zeros(len(held), bool)
    for vp, cov in free_views:
        if len(cov) != len(held):  # not judged on the same samples: nothing to compare
            return [], 0.0
        lost = float((cov & ~held).mean())
        if lost < NOT_FLOWN_LEAST:
            continue
        missed |= cov & ~held
        poses = vp.traj.poses[vp.traj.scanning]
        flange = fit.T_base_part @ poses @ inv_tcp
        report = check_reach(flange, arm)
        cause = np.full(len(vp.traj), -1)
        cause[np.flatnonzero(vp.traj.scanning)[report.unreachable]] = CAUSES.index("reach")
        beyond = beyond_reach_mm(vp.traj, arm, fit.T_base_part, inv_tcp, cause)
        out.append(
            {
                "axis": [round(float(v), 3) for v in vp.view.axis],
                "in_spec_lost": round(lost, 4),
                "scanning_poses": len(poses),
                "out_of_reach": len(report.unreachable),
                "beyond_joint_limits": len(report.limit_violations),
                "beyond_reach_mm": None if beyond is None else round(beyond, 1),
            }
        )
    return sorted(out, key=lambda v: -v["in_spec_lost"]), round(float(missed.mean()), 4)
