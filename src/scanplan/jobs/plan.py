"""`plan`: a part planned into a plan file (views, passes, the arm if any), and the lines
that say what it holds and what it cost.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from scanplan.core.context import LOWEST
from scanplan.core.limits import TCP_MM
from scanplan.core.plan import Plan
from scanplan.core.plan_file import as_read, write_csv, write_json
from scanplan.core.quantities import COVERAGE_TARGET, OVERLAP, VIEW_CHOICE_CANDIDATES, ScanSpec
from scanplan.judging.verdict import (
    FIGURES,
    Criterion,
    Verdict,
    check_available,
    figures_of,
    judge,
    verdict_lines,
)
from scanplan.planning.pipeline import Arm, plan_views
from scanplan.planning.view_budget import ViewBudget
from scanplan.rl.planners import make_planner
from scanplan.robot.axes import combined, load_positioner, track_of
from scanplan.robot.export import parse_pose_arg
from scanplan.robot.export.rotations import IDENTITY_POSE
from scanplan.robot.hints import across_flange, facing, what_would_help, why_not
from scanplan.robot.presets import get_robot
from scanplan.robot.program import program_cycle
from scanplan.world.part import load_part

Lines = list[tuple[str, bool]]  # (line, to stderr)
# What `plan` measures itself; the other figures need the scan simulated.
NOT_MEASURED_BY_PLAN = "is measured by evaluate or compare, not by plan"


@dataclass(frozen=True)
class Planned:
    """What one part's plan says: its lines and its verdicts (none without --require)."""

    lines: Lines
    verdicts: list[Verdict] = field(default_factory=list)

    @property
    def failed(self) -> bool:
        return any(not v.passed for v in self.verdicts)


@dataclass(frozen=True)
class PlanJob:
    """One part's `scanplan plan`, picklable: what a worker process or a Dask task plans."""

    part: str
    output: Path
    planner: str
    spec: ScanSpec
    policy: Path | None = None
    direction: str = "auto"
    overlap: float = OVERLAP
    raster: str = "auto"
    roll: bool = True
    units: str = "mm"
    roi: str | None = None
    views: str | None = None
    coverage_target: float = COVERAGE_TARGET
    table: str | None = None
    fixture: tuple[str, ...] = ()
    robot: str | None = None
    tcp: str | None = None
    part_pose: str | None = None
    view_candidates: int = VIEW_CHOICE_CANDIDATES
    view_seconds: float | None = None  # a wall-clock limit only where the user asks
    scheduler: str | None = None  # one part's candidate views on this Dask scheduler
    require: tuple[Criterion, ...] = ()  # --require: the criteria its verdict holds it to
    positioner: str | None = None  # --positioner: a preset or a TOML file
    track: float | None = None  # --track LENGTH_MM

    def budget(self) -> ViewBudget:
        return ViewBudget(self.view_candidates, self.view_seconds)

    def check_require(self) -> None:
        """A criterion `plan` cannot judge is named before any work."""
        measured = {"cycle"} | ({"arm-cost"} if self.robot is not None else set())
        missing = {k: NOT_MEASURED_BY_PLAN for k in FIGURES if k not in measured}
        if self.robot is None:
            missing["arm-cost"] = "needs --robot"
        check_available(self.require, missing)


def robot_arm(job: PlanJob) -> tuple[Arm | None, Lines]:
    """The arm `plan --robot` makes the plan for (None: no robot), and a note where the TCP
    is the flange because none was given."""
    if job.robot is None:
        for option, value in (
            ("--tcp", job.tcp),
            ("--part-pose", job.part_pose),
            ("--positioner", job.positioner),
            ("--track", job.track),
        ):
            if value is not None:
                raise ValueError(f"{option} needs --robot: the arm it refers to")
        return None, []
    notes: Lines = []
    if job.tcp is None:
        notes.append((f"--tcp not given: {IDENTITY_POSE} (the sensor origin is the flange)", False))
    pose = None if job.part_pose is None else parse_pose_arg(job.part_pose)
    axes = combined(
        None if job.positioner is None else load_positioner(job.positioner),
        None if job.track is None else track_of(job.track),
    )
    # Several brackets, `A;B`: the plan is made with the one the arm flies most with.
    brackets = tuple(parse_pose_arg(t, TCP_MM) for t in (job.tcp or IDENTITY_POSE).split(";"))
    return Arm(job.robot, brackets[0], pose, axes, brackets if len(brackets) > 1 else ()), notes


def run_plan_job(job: PlanJob, progress: Callable[[int, int], None] | None = None) -> Planned:
    """Plan `job`, write its plan, and return what to print and its verdicts."""
    job.budget()  # a bad budget is named before the part is read
    the_part = load_part(job.part, job.units)
    the_planner = make_planner(job.planner, job.policy, job.roll)
    arm, notes = robot_arm(job)
    _, traj = plan_views(
        the_part,
        job.spec,
        the_planner,
        job.views,
        job.coverage_target,
        job.raster,
        job.direction,
        job.overlap,
        roi=job.roi,
        progress=progress,
        table=job.table or LOWEST,
        fixtures=job.fixture,
        fixture_units=job.units,
        arm=arm,
        budget=job.budget(),
        scheduler=job.scheduler,
    )
    # Timed as read back: a program's thinning and blends may turn on the last digit.
    plan = Plan.of(as_read(traj, job.output), f"plan {job.output}")
    cycle = program_cycle(plan)
    traj = replace(traj, meta=traj.meta | {"cycle_time_s": round(cycle.total_s, 3)})
    (write_json if job.output.suffix.lower() == ".json" else write_csv)(traj, job.output)
    verdicts = judge(job.require, figures_of(arm=traj.meta.get("robot"), cycle_s=cycle.total_s))
    lines: Lines = [
        *notes,
        (
            f"{the_planner.name}: {plan.counts()}, {traj.path_length_mm():.0f} mm, "
            f"planned in {traj.plan_time_s:.2f} s -> {job.output}",
            False,
        ),
        (cycle.line(), False),
        *plan_notes(plan),
        *((line, False) for line in verdict_lines(verdicts)),
    ]
    return Planned(lines, verdicts)


def plan_notes(plan: Plan) -> Lines:
    """What the planner left out or overrode, one line each; none when all went to plan."""
    meta, spec = plan.traj.meta, plan.spec
    lines: Lines = []
    if unreachable := meta.get("views_unreachable", 0):
        lines.append((f"views: {unreachable} left out, no collision-free move reaches them", False))
    if dropped := meta.get("collisions_dropped", 0):
        lines.append(
            (
                f"collisions: {dropped} scanning poses dropped (sensor body within "
                f"{spec.clearance_mm:g} mm of the part, the table or a fixture): the plan "
                "is still safe, as it never goes there; what they would have measured is "
                "lost, and the in-spec coverage counts it",
                False,
            )
        )
    if budget := meta.get("view_choice_out_of_budget"):
        lines.append(
            (
                f"views: the choice stopped at its budget ({budget}) with the views chosen by "
                "then (--view-candidates gives it more)",
                False,
            )
        )
    if unreached := meta.get("unreachable_dropped", 0):
        lines.append(
            (
                f"moves: {unreached} scanning poses given up (no move clear of the part and "
                "the cell reaches the piece of pass they are on)",
                False,
            )
        )
    if plan.arm is not None:
        lines += _arm_notes(plan)
    if overrides := {k: v for k, v in meta.items() if k.endswith("_overrides") and v}:
        # The rl planner's guards replaced some of the policy's steps: say how many.
        lines.append(("guard steps: " + ", ".join(f"{k} {v}" for k, v in overrides.items()), False))
    return lines


def _across_flange(robot: str, tcp: np.ndarray) -> str | None:
    """`hints.across_flange` for the plan's arm (None if its file is no longer there)."""
    try:
        arm = get_robot(robot)
    except (OSError, ValueError):
        return None
    return across_flange(robot, arm.flange_axis, tcp)


def _stance_line(stands: dict) -> str:
    """Where the arm's base stands, for setting up the cell (`links.where_it_stands`)."""
    x, y, z = stands["base_in_part_mm"]
    at = f"its base at ({x:g}, {y:g}, {z:g}) mm in the part's frame"
    if stands["on_table"]:
        return f"the arm stands on the table's top, {at}, {stands['above_top_mm']:g} mm above it"
    height = stands["above_top_mm"]
    level = f"{abs(height):g} mm {'above' if height >= 0 else 'below'} the top"
    edge = f"{stands['from_edge_mm']:g} mm off its edge"
    if stands.get("level_with_top"):
        return f"the arm stands level with the table's top beside it, {at}, {edge}, {level}"
    return f"the arm stands beside the table, {at}, {edge}, {level}"


def _arm_notes(plan: Plan) -> Lines:
    assert plan.arm is not None
    arm, record = plan.arm, plan.arm.record
    by_view = record.get("scanning_poses_given_up", {})
    free, flown = arm.coverage or (0.0, 0.0)
    lines: Lines = [
        (
            f"{arm.robot} at --part-pose {record.get('part_pose', '')}: in-spec coverage "
            f"{free:.3f} without the arm, {flown:.3f} flown by it ({flown - free:+.3f}); "
            f"{sum(by_view.values())} scanning poses given up, "
            f"{record.get('moves_given_up', 0)} move poses, {record.get('passes_split', 0)} "
            "passes split at a configuration flip or a joint swing, "
            f"{record.get('passes_turned', 0)} turned half a turn about the beam, "
            f"{record.get('passes_reversed', 0)} flown the other way (links kept clear of the "
            "part, table and fixtures)",
            False,
        )
    ]
    if stands := record.get("stands"):
        lines.append((_stance_line(stands), False))
    if across := _across_flange(arm.robot, arm.T_flange_sensor):
        lines.append((f"note: {across}", False))
    if brackets := record.get("brackets"):
        said = [
            f"--tcp {b['tcp']} flies {b['in_spec_flown']:.3f}" + (" (used)" if b["used"] else "")
            for b in brackets
        ]
        lines.append(("brackets, of the plan made without the arm: " + "; ".join(said), False))
    if (axes := record.get("external_axes")) is not None:
        travel = ", ".join(
            f"{name.rsplit('_', 1)[0]} {t:g} {name.rsplit('_', 1)[1]}"
            for name, t in zip(axes.get("names", []), axes.get("travel", []), strict=False)
        )
        mount = (axes.get("track") or {}).get("mount")
        hung = " (the track overhead: the arm hung upside down)" if mount == "overhead" else ""
        names = ", ".join(axes.get("names", []))
        lines.append((f"external axes: {names}{hung}; travel {travel}", False))
    lost = record.get("in_spec_lost_by_view", {})
    causes = record.get("given_up_by_cause", {})
    worst = sorted(lost, key=lambda k: -lost[k])[:5]
    if worst:
        said = [
            f"view {k} -{lost[k]:.3f} ("
            + ", ".join(f"{c} {n}" for c, n in causes.get(k, {}).items())
            + ")"
            for k in worst
        ]
        lines.append(("what the arm cost, the worst views: " + "; ".join(said), False))
    if missed := record.get("free_views_not_flown"):
        said = [
            f"facing {facing(v['axis'])} -{v['in_spec_lost']:.3f} ({why_not(v)})"
            for v in missed[:5]
        ]
        lines.append(
            ("views of the plan without the arm it flies none of: " + "; ".join(said), False)
        )
    lines += [(f"what would help: {hint}", False) for hint in what_would_help(record)[:3]]
    if not arm.flyable:
        lines.append(
            (f"warning: {arm.robot} still cannot fly every pass; export will say where", True)
        )
    return lines
