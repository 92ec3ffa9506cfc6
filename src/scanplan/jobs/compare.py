"""`compare`: parts (and planners, views) side by side — each planned, its scan judged, and
optionally its plan flown by an arm, perturbed and searched for dents — one row each, by the
jobs `plan`, `evaluate`, `defects` run as a user would run them one by one.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from scanplan.core.plan import read_plan
from scanplan.jobs.defects import DefectStudy, run_defects
from scanplan.jobs.evaluate import Trials, evaluate_plan, judged_part, run_trials
from scanplan.jobs.plan import PlanJob, run_plan_job
from scanplan.jobs.planned import judged_context
from scanplan.judging.report.comparison import Row
from scanplan.judging.verdict import Criterion, check_available, figures_of, judge
from scanplan.world.part_list import PartRef


@dataclass(frozen=True)
class Comparison:
    """What to compare: every part × planner × views, planned as `plan` (its part, planner,
    views and output replaced per row; `plan.robot` flies them) into `plans`, judged with
    `points` columns and `seed`; `trials` and `defects` when asked, `require` each row's
    criteria."""

    parts: tuple[PartRef, ...]
    plan: PlanJob
    plans: Path
    planners: tuple[str, ...] = ("geometric",)
    views: tuple[str | None, ...] = (None,)
    points: int | None = None
    seed: int = 0
    trials: Trials | None = None
    defects: DefectStudy | None = None
    require: tuple[Criterion, ...] = ()

    def check(self) -> None:
        """A criterion no row will measure is named before any work."""
        missing: dict[str, str] = {}
        if self.trials is None:
            missing |= dict.fromkeys(("p5", "worst"), "needs --perturb")
        if self.defects is None:
            missing["pod-a90"] = "needs --defects"
        if self.plan.robot is None:
            missing["arm-cost"] = "needs --robot"
        check_available(self.require, missing)

    def rows(self) -> list[tuple[PartRef, str, str | None]]:
        return [(p, pl, v) for p in self.parts for pl in self.planners for v in self.views]


def compare(job: Comparison, said: Callable[[str], None] = lambda _: None) -> list[Row]:
    """Every row of `job`, in the order asked (`comparison.hardest_first` sorts them); a row
    that fails is one error row and the others still run."""
    job.check()
    job.plans.mkdir(parents=True, exist_ok=True)
    rows = []
    todo = job.rows()
    for k, (ref, planner, views) in enumerate(todo, 1):
        label = f"{ref.name} ({planner}{f', {views} views' if views else ''})"
        said(f"[{k}/{len(todo)}] {label}")
        started = time.perf_counter()
        try:
            row = _row(job, ref, planner, views)
        except (ValueError, OSError) as exc:
            text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            row = Row(_shown(ref), planner, views or "", job.plan.robot or "", error=text)
        said(f"[{k}/{len(todo)}] {label}: {row.summary()} ({time.perf_counter() - started:.0f} s)")
        rows.append(row)
    return rows


def _row(job: Comparison, ref: PartRef, planner: str, views: str | None) -> Row:
    """One part planned by `planner` with `views`, judged as `evaluate` judges it."""
    views_name = views or "default"
    output = job.plans / f"{ref.stem}-{planner}-{views_name}.json"
    units = ref.units_or(job.plan.units)
    planned = run_plan_job(
        replace(job.plan, part=ref.source, units=units, planner=planner, views=views, output=output)
    )
    plan = read_plan(output)
    context, _ = judged_context(plan, None, None, None, None)
    part = judged_part(plan, None, None, context)
    metrics = evaluate_plan(plan, part, context, job.seed, job.points)
    robust = None
    if job.trials is not None:
        robust = run_trials(plan, part, context, job.trials, job.seed, job.points)
    pod_a90 = None
    if job.defects is not None:
        fit = run_defects(plan, part, context, job.defects).result.fit
        # Every defect found: a90 lies below the smallest size tried, its bound here.
        every = fit.status == "all_hit" and len(fit.sizes_mm)
        pod_a90 = float(fit.sizes_mm.min()) if every else fit.a90
    arm = plan.arm.record if plan.arm is not None else None
    figures = figures_of(metrics, robust, arm, pod_a90_mm=pod_a90)
    notes = tuple(text for text, _ in planned.lines[2:])  # what plan said beyond its summary
    return Row(
        _shown(ref),
        plan.planner or planner,
        plan.context.views,
        job.plan.robot or "",
        figures=figures,
        verdicts=tuple(judge(job.require, figures)),
        plan_file=str(output),
        notes=notes,
    )


def _shown(ref: PartRef) -> str:
    """The part as a table names it: its file's name (stems are distinct), or built-in name."""
    return Path(ref.name).name


def failed_rows(rows: Sequence[Row]) -> tuple[int, int]:
    """(rows in error, rows failing a criterion)."""
    return sum(r.error is not None for r in rows), sum(r.failed for r in rows)
