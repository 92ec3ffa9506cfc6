"""`evaluate`: a plan's scan simulated and judged as the plan records it, its cycle timed as
its program flies, and (with a perturbation) how its in-spec coverage holds over trials.
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from scanplan.core.context import PlanContext
from scanplan.core.plan import Plan
from scanplan.core.quantities import PERTURB_TRIALS
from scanplan.core.run import counted, task_runner
from scanplan.jobs.planned import (
    ProgressBar,
    Say,
    inspected,
    no_bar,
    plan_cell,
    planned_part,
    silent,
)
from scanplan.jobs.trials import (
    closed_loop_planner,
    closed_loop_robustness,
    closed_loop_tasks,
    plan_views_of,
)
from scanplan.judging import Metrics, Robustness, robustness, trial_tasks
from scanplan.judging.survey import evaluate_detectable
from scanplan.judging.verdict import Verdict
from scanplan.robot.program import program_cycle
from scanplan.sensor.perturb import Perturbation
from scanplan.world.part import Part

Progress = Callable[[int, int], None] | None


@dataclass(frozen=True)
class Trials:
    """Perturbation trials of a plan: the perturbation, how many, on which scheduler (None:
    the cores here), and whether its controller runs again on each (closed loop, with
    `policy` for an rl plan) or the plan is replayed."""

    model: Perturbation
    count: int = PERTURB_TRIALS
    scheduler: str | None = None
    closed_loop: bool = False
    policy: str | None = None


def judged_part(
    plan: Plan,
    part: str | None,
    units: str | None,
    context: PlanContext,
    other_part: bool = False,
    say: Say = silent,
) -> Part:
    """The plan's part (checked to be the planned one) with its cell built, so that a bad
    ROI, table or fixture fails before the long part."""
    the_part = planned_part(plan, part, units, other_part=other_part, say=say)
    plan_cell(plan, inspected(plan, the_part, context), context)
    return the_part


def check_trials(plan: Plan, context: PlanContext, trials: Trials | None) -> None:
    """A plan the closed loop cannot run is said before any work."""
    if trials is not None and trials.closed_loop:
        closed_loop_planner(context, trials.policy, plan.where)
        plan_views_of(plan.traj, plan.where)


def evaluate_plan(
    plan: Plan,
    part: Part,
    context: PlanContext,
    seed: int = 0,
    points: int | None = None,
    progress: Progress = None,
) -> Metrics:
    """The plan's scan judged by `context`; its cycle time the program's (`program_cycle`),
    the same figure `plan` and `export` print."""
    metrics = evaluate_detectable(
        part, context.spec, plan.traj, seed, points, progress=progress, context=context
    )
    cycle = program_cycle(plan)
    return replace(
        metrics,
        cycle=cycle,
        cycle_time_s=cycle.total_s,
        scan_time_s=cycle.scanning_s,
        move_time_s=cycle.moving_s,
    )


def run_trials(
    plan: Plan,
    part: Part,
    context: PlanContext,
    trials: Trials,
    seed: int = 0,
    points: int | None = None,
    bar: ProgressBar = no_bar,
) -> Robustness:
    """The in-spec coverage of `plan` over seeded perturbed parts."""
    if trials.closed_loop:
        tasks: Any = closed_loop_tasks(
            part, plan.traj, context, trials.model, trials.count, seed, points, trials.policy,
            plan.where,
        )  # fmt: skip
        collect: Any = closed_loop_robustness
    else:
        tasks = trial_tasks(
            part, context.spec, plan.traj, trials.model, trials.count, seed, points,
            context=context,
        )  # fmt: skip
        collect = robustness
    with bar("trials") as progress, task_runner(trials.scheduler, trials.count) as run:
        return collect(tasks, counted(run, progress))


def write_evaluation(
    output: Path,
    plan: Plan,
    part: Part,
    context: PlanContext,
    metrics: Metrics,
    robust: Robustness | None,
    full_3d: bool = False,
    verdicts: Sequence[Verdict] = (),
) -> None:
    """The report folder: maps, metrics, report.html, and the fragility map of the trials;
    the report tells the arm and what it cost, the trials and the verdicts."""
    # Deferred: the report loads matplotlib and plotly.
    from scanplan.judging.report import Evaluated, write_report
    from scanplan.judging.report.findings import arm_finding, robustness_finding, verdict_finding
    from scanplan.judging.report.maps import plot_fragility_map

    name = Path(plan.where.removeprefix("plan ")).name
    title = f"{part.name}: {name}"
    # The fragility map is made aside and goes into the report's folder with the rest, so
    # the folder is swapped in whole or not at all.
    with tempfile.TemporaryDirectory() as scratch:
        files: dict[str, str | bytes | Path] = {}
        if robust is not None:
            files = {"fragility.csv": Path(scratch, "fragility.csv")}
            robust.write_csv(files["fragility.csv"])
            files["fragility.png"] = plot_fragility_map(robust, Path(scratch, "f.png"), title)
        write_report(
            output,
            inspected(plan, part, context),
            [Evaluated(plan.planner or Path(name).stem, plan.traj, metrics)],
            context.spec,
            files=files,
            title=title,
            full_3d=full_3d,
            findings=[
                f
                for f in (
                    verdict_finding(verdicts),
                    arm_finding(plan.arm.robot, plan.arm.record) if plan.arm is not None else None,
                    robustness_finding(robust, metrics.in_spec_coverage),
                )
                if f is not None
            ],
        )


def metrics_line(metrics: Metrics, data: dict[str, Any]) -> str:
    """The scan's quality on one line: in-spec coverage first, then the errors behind it."""
    tol = data["tolerance"]
    return (
        f"in-spec coverage {metrics.in_spec_coverage:.1%} (±{tol['mm']:g} mm, {tol['deg']:g}°) "
        f"of the {metrics.surface} surface ({_grouped(metrics.visible_area_mm2)} mm²)"
        f"{_of_ceiling(metrics)}{_detectable(metrics)} | "
        f"coverage {metrics.coverage_fraction:.1%} | {data['profiles']} profiles | "
        f"|distance error| mean {metrics.distance_error_mean_abs_mm:.3f} "
        f"p95 {metrics.distance_error_p95_abs_mm:.3f} mm | orientation mean "
        f"{metrics.orientation_error_mean_deg:.2f} p95 {metrics.orientation_error_p95_deg:.2f} deg"
        f" | spacing {metrics.spacing_mean_mm:.3f} mm (cv {metrics.spacing_cv:.3f}, "
        f"{metrics.backward_steps} backward) | reward {metrics.reward_mean:.4f}"
        f" | collisions {metrics.collisions_count} within {metrics.clearance_mm:g} mm, "
        f"{metrics.collisions_touching} touching (worst {metrics.worst_penetration_mm:.1f} mm)"
    )


def _detectable(metrics: Metrics) -> str:
    """' | dent found at 90 %: 0.089 mm deep (predicted)', or nothing where not predicted."""
    found = metrics.detectable
    if not found:
        return ""
    a90 = found.get("a90_mm")
    size = f"{a90:.3f} mm deep" if a90 is not None else "none (too little of the surface seen)"
    return f" | {found['type']} found at 90 %: {size} (predicted)"


def _of_ceiling(metrics: Metrics) -> str:
    """', 84.1% of its visibility ceiling 97.3%', or nothing where it was not measured."""
    share = metrics.in_spec_of_ceiling
    if share is None or metrics.visibility_ceiling is None:
        return ""
    return f", {share:.1%} of its visibility ceiling {metrics.visibility_ceiling:.1%}"


def _grouped(value: float) -> str:
    """181 206: thousands grouped by spaces, as the tables print them."""
    return f"{value:,.0f}".replace(",", " ")
