"""Robustness trials of a closed-loop plan (feedback, rl): on each perturbed part the plan's
controller drives the plan's passes again, acting on the profiles of the part as built and
where it really sits, as it would on a cell streaming profiles to the robot; the poses it
flew are then judged as an open-loop plan's trials are (`metrics.robustness.run_trial`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import trimesh

from scanplan.cell import Cell, Table
from scanplan.context import PlanContext
from scanplan.metrics.evaluation import scanning_steps
from scanplan.metrics.robustness import (
    PlacedProfilometer,
    Robustness,
    TrialMap,
    TrialTask,
    run_trial,
    summarize,
    trial_tasks,
    trial_world,
)
from scanplan.part import Part
from scanplan.perturb import Perturbation
from scanplan.pipeline import plan_path
from scanplan.planners import FeedbackPlanner
from scanplan.quantities import UP, ScanSpec
from scanplan.sensor import SensorSpec
from scanplan.swaths import Swath, swath_from_record
from scanplan.trajectory import Trajectory

# The planners whose controller acts on measured profiles: the only ones a closed loop re-runs.
CLOSED_LOOP_PLANNERS = ("feedback", "rl")


@dataclass(frozen=True)
class ClosedLoopTask:
    """One closed-loop trial, picklable (no ray engine): `judge` the open-loop trial task
    whose poses the closed loop replaces; `planner` the feedback or rl planner (its
    `measure_with` set in the worker); `swaths` the plan's pass lines (part frame); the cell
    as planned: `table` (None: held in the air), `table_z_mm`, `fixtures` (vertices, faces,
    name) each; `spec` the plan's ScanSpec."""

    judge: TrialTask
    planner: Any
    swaths: tuple[Swath, ...]
    table: Table | None
    table_z_mm: float | None
    fixtures: tuple[tuple[np.ndarray, np.ndarray, str], ...]
    spec: ScanSpec


def run_closed_loop_trial(task: ClosedLoopTask) -> np.ndarray:
    """(k,) bool: which nominal surface samples the closed loop holds in spec on trial
    `task.judge.index`. The passes are planned as `pipeline.plan_path` plans them on the CAD
    (where each starts and ends, the table's tilt limit, the poses dropped for the clearance
    to the nominal part and cell), but every profile the controller acts on is measured on
    the part as built and placed. The robot's path error is not seen by the controller: it
    is drawn on the poses flown, as in the open-loop trials."""
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

    def measured(_: Part, sensor: SensorSpec) -> PlacedProfilometer:
        return PlacedProfilometer(world.part, sensor, world.T_part_placed)

    planner = replace(task.planner, measure_with=measured)
    traj = plan_path(nominal, task.spec, planner, list(task.swaths), cell=cell)
    idx, has_prev = scanning_steps(traj)
    return run_trial(replace(judge, poses=traj.poses[idx], has_prev=has_prev))


def plan_swaths_of(traj: Trajectory, where: str) -> list[Swath]:
    """The pass lines a plan records, for running it in closed loop; ValueError (one line)
    for a plan that has none or more than one view, or was fitted to a robot."""
    if traj.meta.get("robot"):
        raise ValueError(
            f"{where} was fitted to a robot (passes split or turned): the closed loop runs "
            "the plan as planned on the CAD; evaluate the plan made without --robot"
        )
    views = traj.meta.get("views") or []
    if len(views) != 1:
        raise ValueError(
            f"{where} has {len(views)} views: the closed loop runs plans of one view "
            "looking straight down (plan with --views top)"
        )
    view = views[0]
    if not np.allclose(view["axis"], UP, atol=1e-9):
        raise ValueError(f"{where}: its view looks along {view['axis']}, not straight down")
    records = view.get("swaths")
    if not records:
        raise ValueError(
            f"{where} does not record its pass lines (made by an older scanplan): plan it "
            "again to run it in closed loop"
        )
    swaths = [swath_from_record(r, f"{where}: views[0].swaths[{i}]") for i, r in enumerate(records)]
    planned = set(np.unique(traj.swath[traj.scanning]).tolist())
    if not planned <= {sw.index for sw in swaths}:
        raise ValueError(f"{where}: its pass lines do not match its passes")
    return swaths


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
    from scanplan.planners.rl import RLPlanner

    rl = RLPlanner.from_file(policy if policy is not None else default_policy(context))
    if rl.roll != context.full_beam_angle:
        kind = "rolls" if context.full_beam_angle else "does not roll"
        raise ValueError(f"{where} {kind}; {rl.source} {'does' if rl.roll else 'does not'}")
    rl.check_sensor(context.spec)
    return rl


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
    """The `trials` tasks of a closed-loop robustness run of `traj` (a feedback or rl plan
    of one top view), judged as `metrics.robustness.trial_tasks` judges its replay."""
    planner = closed_loop_planner(context, policy, where)
    swaths = tuple(plan_swaths_of(traj, where))
    judges = trial_tasks(
        part, context.spec, traj, model, trials, seed, points_per_profile, context=context
    )
    cell = context.cell(part.with_roi(context.roi))
    fixtures = tuple(
        (np.asarray(f.mesh.vertices), np.asarray(f.mesh.faces), f.name) for f in cell.fixtures
    )
    return [
        ClosedLoopTask(j, planner, swaths, cell.table, cell.table_z_mm, fixtures, context.spec)
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
