"""Robustness trials of a closed-loop plan (feedback, rl): on each perturbed part the plan's
controller drives the plan's passes again, view by view, acting on the profiles of the part
as built and where it really sits, as it would on a cell streaming profiles to the robot;
the poses it flew are then judged as an open-loop plan's trials are
(`metrics.robustness.run_trial`).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import trimesh

from scanplan.core.context import PlanContext
from scanplan.core.limits import MAX_POSES, check_count
from scanplan.core.plan import ArmRecord, Plan, ViewRecord
from scanplan.core.plan_records import region_faces
from scanplan.core.quantities import UP, ScanSpec
from scanplan.core.sensor_spec import SensorSpec
from scanplan.core.trajectory import Trajectory
from scanplan.judging.evaluation import scanning_steps
from scanplan.judging.robustness import (
    Robustness,
    TrialMap,
    TrialTask,
    TrialWorld,
    run_trial,
    summarize,
    trial_tasks,
    trial_world,
)
from scanplan.planning.arm_guard import HALF_TURN, ArmGuard, PieceNominal, fitted_pieces
from scanplan.planning.dynamics import step_budget
from scanplan.planning.pass_path import plan_path
from scanplan.planning.planners import FeedbackPlanner
from scanplan.planning.swaths import Swath, swath_from_record
from scanplan.planning.views import View, rotation_to_up
from scanplan.sensor.perturb import Perturbation
from scanplan.sensor.placed import PlacedProfilometer
from scanplan.world.cell import Cell, Table, planned_cell
from scanplan.world.part import Part

# The planners whose controller acts on measured profiles: the only ones a closed loop re-runs.
CLOSED_LOOP_PLANNERS = ("feedback", "rl")


@dataclass(frozen=True)
class ViewLines:
    """One view of a plan as its file records it: `view` (its axis and rotation; no region,
    the file does not keep it) and `swaths`, its pass lines in the view's frame, numbered
    as the plan's passes. A plan fitted to an arm: `pieces`, its passes as pieces of those
    lines with the plan's states along each (`arm_guard.fitted_pieces`), flown instead."""

    view: View
    swaths: tuple[Swath, ...]
    pieces: tuple[PieceNominal, ...] = ()

    @property
    def flown(self) -> list[Swath]:
        """The lines the controller flies: the pieces of a fitted plan, else the lines."""
        return [p.swath for p in self.pieces] if self.pieces else list(self.swaths)


@dataclass(frozen=True)
class ClosedLoopTask:
    """One closed-loop trial, picklable (no ray engine): `judge` the open-loop trial task
    whose poses the closed loop replaces; `planner` the feedback or rl planner (its
    `measure_with` set in the worker); `views` the plan's views and pass lines; the cell
    as planned: `table` (None: held in the air), `table_z_mm`, `fixtures` (vertices, faces,
    name) each; `spec` the plan's ScanSpec; `arm` the arm a fitted plan was fitted to (the
    controller's corrections are kept within it, `arm_guard.ArmGuard`). knows_part: the
    planner (any, open-loop ones too) plans the same pass lines on the part as built and
    where it lies instead, as if it knew it exactly: the ceiling of any controller on those
    lines."""

    judge: TrialTask
    planner: Any
    views: tuple[ViewLines, ...]
    table: Table | None
    table_z_mm: float | None
    fixtures: tuple[tuple[np.ndarray, np.ndarray, str], ...]
    spec: ScanSpec
    arm: ArmRecord | None = None  # a fitted plan's arm: the corrections kept within it
    knows_part: bool = False  # the planner plans on the part as it is (the re-plan ceiling)


def run_closed_loop_trial(task: ClosedLoopTask) -> np.ndarray:
    """(k,) bool: which nominal surface samples the closed loop holds in spec on trial
    `task.judge.index` (the poses `fly_trial` flew, judged as a replayed plan's)."""
    traj = fly_trial(task)
    if traj is None:
        return np.zeros(len(task.judge.surface.points), bool)
    idx, has_prev = scanning_steps(traj)
    return run_trial(replace(task.judge, poses=traj.poses[idx], has_prev=has_prev))


def fly_trial(task: ClosedLoopTask) -> Trajectory | None:
    """The poses (part frame) the closed loop flies on trial `task.judge.index`; None if
    every view was lost. Each view's passes are planned as `pipeline.plan_views` plans them
    on the CAD turned into the view's frame (where each starts and ends, the table's tilt
    limit, the poses dropped for the clearance to the nominal part and cell), but every
    profile the controller acts on is measured on the part as built and placed, turned the
    same way; the views' poses, back in the part frame, are joined in the plan's order. A
    view whose flown passes no clear move joins is lost for the trial (a warning says so).
    The robot's path error is not seen by the controller: it is drawn on the poses flown,
    as in the open-loop trials."""
    judge = task.judge
    world = trial_world(judge)
    nominal = Part(
        trimesh.Trimesh(judge.vertices, judge.faces, process=False),
        name=judge.name,
        source=judge.name,
        inspect_faces=judge.inspect_faces,
    )
    fixtures = tuple(
        Part(trimesh.Trimesh(v, f, process=False), name=name, source=name)
        for v, f, name in task.fixtures
    )
    cell = Cell(task.table, fixtures, task.table_z_mm)
    nominal = cell.occluding(nominal)  # the CAD the controller probes, among the fixtures
    placed = world.T_part_placed
    there = _part_there(world, judge, cell) if task.knows_part else None
    pieces = []
    for lines in task.views:
        view = lines.view
        # The part as built turned as the CAD is (`View.part`: the very mesh at no
        # perturbation), and its placement error seen from the view's frame.
        built = view.part(world.part)
        R = view.R
        T = placed if np.array_equal(placed, np.eye(4)) else R @ placed @ np.linalg.inv(R)

        def measured(_: Part, sensor: SensorSpec, built=built, T=T) -> PlacedProfilometer:
            return PlacedProfilometer(built, sensor, T)

        planner = (
            task.planner if there is not None else replace(task.planner, measure_with=measured)
        )
        if task.arm is not None:
            planner = replace(planner, arm_guard=_guard(task.arm, lines))
        try:
            flown = plan_path(
                view.part(nominal if there is None else there),
                task.spec,
                planner,
                lines.flown,
                cell=cell if np.array_equal(R, np.eye(4)) else cell.rotated(R),
            )
        except ValueError as exc:
            # The controller left a pass where no clear move (checked on the CAD) reaches
            # the next: the cell would stop this view; the trial goes on without it, as
            # `view_joining.join_views` leaves out a view no clear move reaches.
            warnings.warn(f"trial {judge.index}: view {view.index} lost: {exc}", stacklevel=1)
            continue
        if lines.pieces:
            turned = [p.swath.index for p in lines.pieces if p.turned]
            turn = np.isin(flown.swath, turned)[:, None, None]
            flown = replace(flown, poses=np.where(turn, flown.poses @ HALF_TURN, flown.poses))
        pieces.append(view.to_part_frame(flown))
    return Trajectory.concatenate(pieces) if pieces else None


def _guard(arm: ArmRecord, lines: ViewLines) -> ArmGuard:
    """The arm a fitted plan's view is flown by, keeping the controller's corrections."""
    return ArmGuard(
        arm.robot,
        arm.T_base_part,
        arm.T_flange_sensor,
        lines.view.R,
        {p.swath.index: p for p in lines.pieces},
    )


def _part_there(world: TrialWorld, judge: TrialTask, cell: Cell) -> Part:
    """The part as built, where it lies (in the nominal frame), among the cell's fixtures."""
    mesh = world.part.mesh.copy()
    mesh.apply_transform(world.T_part_placed)
    part = Part(mesh, name=judge.name, source=judge.name, inspect_faces=judge.inspect_faces)
    return cell.occluding(part)


def plan_views_of(traj: Trajectory, where: str, n_faces: int | None = None) -> list[ViewLines]:
    """The views, their regions and pass lines a plan records, in its order, for running it
    in closed loop (a plan fitted to an arm: its passes as pieces of those lines,
    `ViewLines.pieces`); ValueError (one line) for a plan that records none, or a region
    not of a part of `n_faces` faces (None: of the part it records)."""
    plan = Plan.of(traj, where)
    if not plan.views:
        raise ValueError(f"{where} records no views: plan it again to run it in closed loop")
    out = []
    for k, view in enumerate(plan.views):
        lines = view.record.get("swaths")
        if not lines:
            raise ValueError(
                f"{where} does not record its pass lines (made by an older scanplan): plan "
                "it again to run it in closed loop"
            )
        axis = np.array(view.axis, dtype=np.float64)
        if abs(float(np.linalg.norm(axis)) - 1.0) >= 1e-6:
            axis = axis / np.linalg.norm(axis)  # a file's axis is unit to 1e-3: to the bit
        swaths = tuple(
            swath_from_record(r, f"{where}: views[{k}].swaths[{i}]") for i, r in enumerate(lines)
        )
        region = view.record.get("region")
        faces = None
        if region is not None:
            count = int(region["faces"]) if n_faces is None else n_faces
            faces = region_faces(region, count, f"{where}: views[{k}]")
        the_view = View(k, axis, rotation_to_up(axis), faces)
        pieces: tuple[PieceNominal, ...] = ()
        if plan.arm is not None:
            pieces = _fitted(traj, plan, view, the_view, swaths)
        out.append(ViewLines(the_view, swaths, pieces))
    planned = set(np.unique(traj.swath[traj.scanning]).tolist())
    if plan.arm is None and not planned <= {sw.index for v in out for sw in v.swaths}:
        raise ValueError(f"{where}: its pass lines do not match its passes")
    # Counted before any work: the steps a trial may take (each pass's episode limit).
    flown = [sw for v in out for sw in v.flown]
    steps = sum(step_budget(sw.length_mm, plan.spec)[1] for sw in flown)
    check_count(
        steps,
        MAX_POSES,
        f"{where}: closed-loop steps of one trial (passes of "
        f"{sum(sw.length_mm for sw in flown):g} mm in steps of "
        f"{plan.spec.delta_s_opt_mm:g} mm, up to 3 times as many)",
    )
    return out


def _fitted(
    traj: Trajectory, plan: Plan, record: ViewRecord, view: View, lines: tuple[Swath, ...]
) -> tuple[PieceNominal, ...]:
    """The passes of one view of a plan fitted to an arm, as pieces of its lines."""
    mine = traj.scanning & (traj.swath >= record.first_swath) & (traj.swath <= record.last_swath)
    poses = view.R[None] @ traj.poses[mine]
    return tuple(
        fitted_pieces(
            list(lines),
            poses,
            traj.swath[mine],
            2 * plan.spec.delta_s_opt_mm,
            roll=plan.context.full_beam_angle,
        )
    )


def plan_swaths_of(traj: Trajectory, where: str) -> list[Swath]:
    """The pass lines of a plan of one view looking straight down (in the part frame, as a
    robot-side loop takes them: `online`); ValueError (one line) for any other plan, whose
    views' lines lie in their own frames (`plan_views_of`)."""
    views = plan_views_of(traj, where)
    if len(views) != 1:
        raise ValueError(
            f"{where} has {len(views)} views, each's pass lines in its own frame: take them "
            "with trials.plan_views_of"
        )
    view = views[0].view
    if not np.allclose(view.axis, UP, atol=1e-9):
        raise ValueError(f"{where}: its view looks along {view.axis.tolist()}, not straight down")
    return list(views[0].swaths)


def closed_loop_planner(context: PlanContext, policy: str | None, where: str) -> Any:
    """The planner that made a closed-loop plan, as its context records it: feedback with
    its roll and step limits, rl with `policy` (None: the shipped policy of the plan's kind,
    v1 if it rolls). ValueError (one line) for any other planner or a policy of the other
    kind."""
    if context.planner not in CLOSED_LOOP_PLANNERS:
        raise ValueError(
            f"--closed-loop re-runs the controller of a feedback or rl plan; {where} was "
            f"made by {context.planner or 'an unknown planner'} (an open-loop plan: "
            "--perturb alone replays it)"
        )
    if policy is not None and context.planner != "rl":
        raise ValueError("--policy is the rl plan's policy: this plan was made by feedback")
    if context.planner == "feedback":
        return FeedbackPlanner(roll=context.full_beam_angle, limits=context.limits)
    # Deferred: the rl planner loads torch, which no other planner needs.
    from scanplan.rl.planner import RLPlanner

    rl = RLPlanner.from_file(policy if policy is not None else default_policy(context))
    if rl.roll != context.full_beam_angle:
        kind = "rolls" if context.full_beam_angle else "does not roll"
        raise ValueError(f"{where} {kind}; {rl.source} {'does' if rl.roll else 'does not'}")
    rl.check_sensor(context.spec)
    return rl


def looks_ahead(planner: Any) -> bool:
    """The planner is an rl policy whose observation probes the CAD ahead of the sensor."""
    return bool(getattr(planner, "config", {}).get("env", {}).get("lookahead", False))


def default_policy(context: PlanContext) -> str:
    """The shipped policy an rl plan was made with when none is given: v1 if it rolls."""
    return "v1" if context.full_beam_angle else "default"


def closed_loop_tasks(
    part: Part,
    traj: Trajectory,
    context: PlanContext,
    model: Perturbation,
    trials: int,
    seed: int = 0,
    points_per_profile: int | None = None,
    policy: str | None = None,
    where: str = "the plan",
) -> list[ClosedLoopTask]:
    """The `trials` tasks of a closed-loop robustness run of `traj` (a feedback or rl plan,
    every view of it), judged as `metrics.robustness.trial_tasks` judges its replay."""
    planner = closed_loop_planner(context, policy, where)
    return controller_tasks(
        part, traj, context, planner, model, trials, seed, points_per_profile, where
    )


def controller_tasks(
    part: Part,
    traj: Trajectory,
    context: PlanContext,
    planner: Any,
    model: Perturbation,
    trials: int,
    seed: int = 0,
    points_per_profile: int | None = None,
    where: str = "the plan",
    knows_part: bool = False,
) -> list[ClosedLoopTask]:
    """The `trials` tasks of `planner` flying the views and pass lines of `traj` (any plan
    that records them, whoever made it) on each perturbed part: in closed loop for a
    feedback or rl planner, or, with `knows_part`, planned on the part as it is (any
    planner: the re-plan ceiling). Judged as `metrics.robustness.trial_tasks` judges the
    replay of `traj`, so every planner given the same plan is judged on the same samples."""
    views = tuple(plan_views_of(traj, where, len(part.mesh.faces)))
    tilted = [v for v in views if not np.array_equal(v.view.R, np.eye(4))]
    if looks_ahead(planner) and any(v.view.faces is None for v in tilted):
        # Its look-ahead probes only the view's region, which an older plan file lacks.
        raise ValueError(
            f"{planner.source} looks ahead on each view's region, which {where} does not "
            "record (made by an older scanplan): plan it again to run it in closed loop"
        )
    if not knows_part and getattr(planner, "name", None) not in CLOSED_LOOP_PLANNERS:
        raise ValueError(f"{planner.name} does not act on measured profiles: no closed loop")
    judges = trial_tasks(
        part, context.spec, traj, model, trials, seed, points_per_profile, context=context
    )
    cell = planned_cell(context, part.with_roi(context.roi))
    fixtures = tuple(
        (np.asarray(f.mesh.vertices), np.asarray(f.mesh.faces), f.name) for f in cell.fixtures
    )
    arm = Plan.of(traj, where).arm
    if arm is not None and knows_part:
        raise ValueError(f"{where} was fitted to an arm: no re-planned ceiling on its passes")
    return [
        ClosedLoopTask(
            j, planner, views, cell.table, cell.table_z_mm, fixtures, context.spec, arm, knows_part
        )
        for j in judges
    ]


def closed_loop_robustness(
    tasks: Sequence[ClosedLoopTask],
    run: TrialMap = map,  # type: ignore[assignment]
) -> Robustness:
    """Run the closed-loop trials with `run` (a map, as `metrics.robustness.robustness`
    takes) and summarize them."""
    if not tasks:
        raise ValueError("no trial to run")
    results = list(run(run_closed_loop_trial, tasks))  # type: ignore[arg-type]
    return summarize(tasks[0].judge, results, closed_loop=True)
