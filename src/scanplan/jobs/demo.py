"""`scanplan demo`, the main job (SPEC §9): the door, the three planners, the numbers, the
pictures, the report and a robot program for a real cell, in a few minutes on 2 cores.

Everything the demo shows comes from the library calls a user makes from the command line
(plan_views, evaluate, write_report, fit_arm, check_flyable, export_program); nothing is
demo-only.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from scanplan.core.context import PlanContext, judged_alike, recorded
from scanplan.core.files import dumps_json
from scanplan.core.plan import Plan, free_and_flown
from scanplan.core.plan_file import to_csv_text, to_json_dict
from scanplan.core.quantities import ScanSpec
from scanplan.core.sensor_spec import DEMO_POINTS
from scanplan.core.trajectory import Trajectory
from scanplan.jobs.second_process import SecondProcess
from scanplan.judging import Metrics
from scanplan.judging.report import Evaluated, write_report
from scanplan.judging.report.findings import Finding, Program, arm_finding
from scanplan.judging.survey import evaluate_detectable
from scanplan.planning.pipeline import Arm, default_views, fit_arm, plan_views
from scanplan.rl.planners import make_planner
from scanplan.robot import get_robot
from scanplan.robot.export import ExportOptions, export_program, parse_pose_arg, parse_program
from scanplan.robot.export.common import plan_motion
from scanplan.robot.flyable import check_flyable
from scanplan.robot.links import obstacles_for
from scanplan.robot.program import program_cycle
from scanplan.world.cell import planned_cell
from scanplan.world.part import Part, load_part

PLANNER_ORDER = ("fixed", "geometric", "rl")
# The cell the rl plan's program is written for: an IRB 2400 (1.55 m reach) takes the 1.4 m
# door; the profilometer on a 90 mm bracket off the flange, pointing along the tool axis.
DEMO_ROBOT = "irb2400"
DEMO_TCP = "0,0,90,0,0,0"
DEMO_FORMAT = "rapid"  # the IRB 2400's language
PROGRAM_FILE = "scan_rl.mod"
FITTED_FILE = f"trajectory_rl_{DEMO_ROBOT}.json"


@dataclass(frozen=True)
class DemoResult:
    out_dir: Path
    metrics: dict[str, Metrics]
    trajectories: dict[str, Trajectory]
    report: Path
    program: Path
    program_error_m: float
    robot_line: str
    seconds: float


def run_demo(
    out_dir: Path,
    part_name: str = "door",
    units: str = "mm",
    spec: ScanSpec | None = None,
    points_per_profile: int | None = DEMO_POINTS,
    seed: int = 0,
    step: Callable[[str], None] = lambda message: None,
    roi: str | None = None,
    full_3d: bool = False,
) -> DemoResult:
    """Plan, evaluate, draw, report and export. `step` is told what is starting (progress);
    `roi`: a region of interest (`part.parse_roi`) that planning and coverage keep to;
    `full_3d`: the report's 3-D views at full resolution (`write_report`).

    Everything is computed first and written at the end by `report.write_report`, as one
    directory that replaces `out_dir` atomically: an interrupted demo leaves no half of one."""
    start = time.perf_counter()
    spec = spec or ScanSpec()
    out_dir = Path(out_dir)
    step(f"loading part {part_name}")
    # The rl plan is fitted to the arm in a second process, beside the other plans, their
    # evaluations and the maps here (threads would share one interpreter). It loads the part
    # meanwhile; rl is planned first so that its fit (the longest step) can start at once,
    # judged on the surface the other planners' default views will make the comparison's
    # (checked once they are planned: refitted if that guess was wrong).
    with SecondProcess(_load_part_here, part_name, units) as second:
        part: Part = load_part(part_name, units)
        plans: dict[str, tuple[int, int, Trajectory]] = {}
        for name in ("rl", *PLANNER_ORDER[:-1]):
            step(f"planning {name}")
            plans[name] = _plan(part, name, spec, roi)
            step(_planned_line(name, plans[name]))
            if name == "rl":
                rl = plans[name][2]
                guess = _judged_guess(rl, spec)
                second.submit(_fit_here, rl, guess, spec)
                step(
                    f"fitting the rl plan to an {DEMO_ROBOT} (placing the part) in a second process"
                )
        trajectories = {name: plans[name][2] for name in PLANNER_ORDER}
        files: dict[str, str | bytes | Path] = {
            f"trajectory_{name}.csv": to_csv_text(traj) for name, traj in trajectories.items()
        }
        # All judged on one surface: a table of figures over different surfaces compares
        # nothing.
        judged = judged_alike([recorded(t, spec) for t in trajectories.values()])
        contexts = dict(zip(trajectories, judged, strict=True))
        if contexts["rl"] != guess:
            second.submit(_fit_here, rl, contexts["rl"], spec)
        metrics: dict[str, Metrics] = {}
        for name in PLANNER_ORDER:
            traj, context = trajectories[name], contexts[name]
            step(
                f"evaluating {name} ({int(traj.scanning.sum())} profiles, "
                f"{context.surface} surface)"
            )
            metrics[name] = _evaluate(part, spec, traj, context, seed, points_per_profile)
        evaluated = [Evaluated(name, trajectories[name], m) for name, m in metrics.items()]
        fit = _FitWait(second, refit=contexts["rl"] != guess, step=step)
        report = _write_report(
            out_dir, part.with_roi(roi), evaluated, spec, files, seed, points_per_profile,
            full_3d, step, fit.program_part,
        )  # fmt: skip
    assert fit.fitted is not None  # the report asked for it
    fitted, robot_line, _, error_m, _, _ = fit.fitted
    return DemoResult(
        out_dir,
        metrics,
        trajectories,
        report,
        out_dir / PROGRAM_FILE,
        error_m,
        robot_line,
        time.perf_counter() - start,
    )


class _FitWait:
    """The second process's fit, waited for only when the report has drawn its maps: the
    program and the fitted plan as files, what the page says of the program (`program_part`)."""

    def __init__(self, second: SecondProcess, refit: bool, step: Callable[[str], None]) -> None:
        self.second, self.refit, self.step = second, refit, step
        self.fitted: tuple[Trajectory, str, str, float, Program, float] | None = None

    def program_part(self) -> tuple[dict[str, str | bytes | Path], list[Finding]]:
        self.fitted = self.second.result()
        if self.refit:  # fitted to the guessed surface first: that one is not the report's
            self.fitted = self.second.result()
        fitted, robot_line, text, _, program, fit_seconds = self.fitted
        self.step(f"{robot_line} ({fit_seconds:.0f} s)")
        arm = Plan.of(fitted).arm
        assert arm is not None  # fitted: it records its arm
        fitted_note = (
            f"The tables below judge the rl plan without the arm; the program flies {FITTED_FILE}."
        )
        said = arm_finding(DEMO_ROBOT, arm.record, program, DEMO_TCP, fitted_note)
        # The fitted plan records the arm, part pose and TCP: `scanplan export` takes it as is.
        files: dict[str, str | bytes | Path] = {
            PROGRAM_FILE: text,
            FITTED_FILE: dumps_json(to_json_dict(fitted), indent=1),
        }
        return files, [said]


def _write_report(
    out_dir: Path,
    part: Part,
    evaluated: list[Evaluated],
    spec: ScanSpec,
    files: dict[str, str | bytes | Path],
    seed: int,
    points_per_profile: int | None,
    full_3d: bool,
    step: Callable[[str], None],
    program_part: Callable[[], tuple[dict[str, str | bytes | Path], list[Finding]]],
) -> Path:
    """`report.write_report` of the demo's plans, with the shipped policy's training curves
    and log, and `files` written beside it, and the program's files and finding once the
    maps are drawn (`program_part`); its path."""
    # Deferred: the rl planner's module loads torch.
    from scanplan.rl.planner import DEFAULT_POLICY

    training_log, curves = _training_files(DEFAULT_POLICY)
    files = {**files, **curves}  # the curves' pictures in the folder; the page draws the log
    if training_log is not None:
        files["training_log.csv"] = training_log
    step("drawing the maps and writing the report")
    sensor = spec.sensor
    fan = f"{points_per_profile} of {sensor.points_per_profile}" if points_per_profile else "all"
    return write_report(
        out_dir,
        part,
        evaluated,
        spec,
        pictures=[] if training_log is not None else list(curves.values()),
        notes=[
            f"Evaluated with {fan} pixel columns per profile, noise seed {seed}.",
            "Planned one after another (rl first) while a second process loaded the part and "
            "fitted the rl plan to the arm: the plan times include sharing the CPU with it.",
        ],
        training_log=training_log,
        files=files,
        title=f"{part.name}: scan quality by planner",
        full_3d=full_3d,
        later=program_part,
    )


def _plan(part: Part, name: str, spec: ScanSpec, roi: str | None) -> tuple[int, int, Trajectory]:
    """(views, passes, trajectory) of planner `name` with its own default views."""
    plans, traj = plan_views(part, spec, make_planner(name), roi=roi)
    return len(plans), sum(p.passes for p in plans), traj


def _planned_line(name: str, planned: tuple[int, int, Trajectory]) -> str:
    views, passes, _ = planned
    return f"planned {name}: {views} view{'s' * (views > 1)}, {passes} passes"


def _evaluate(
    part: Part,
    spec: ScanSpec,
    traj: Trajectory,
    context: PlanContext,
    seed: int,
    points_per_profile: int | None,
) -> Metrics:
    """The demo's figures of one plan, its cycle timed as the exported program flies it:
    between its thinned targets."""
    motion = plan_motion(traj, ExportOptions(scan=spec))
    return evaluate_detectable(
        part,
        spec,
        traj,
        seed,
        points_per_profile,
        context=context,
        targets=motion.source,
        blended=motion.blend_mm > 0,
    )


# The second process's part (`_load_part_here`); None in the main process.
_part_here: Part | None = None


def _load_part_here(part_name: str, units: str) -> None:
    global _part_here
    _part_here = load_part(part_name, units)


def _loaded_part() -> Part:
    if _part_here is None:
        raise RuntimeError("no part loaded in this process")
    return _part_here


def _fit_here(
    traj: Trajectory, context: PlanContext, spec: ScanSpec
) -> tuple[Trajectory, str, str, float, Program, float]:
    """`_robot_program`, and the seconds it took."""
    started = time.perf_counter()
    out = _robot_program(_loaded_part(), traj, context, spec)
    return (*out, time.perf_counter() - started)


def _judged_guess(rl: Trajectory, spec: ScanSpec) -> PlanContext:
    """The rl plan's context as `judged_alike` will make it, told before the other plans
    are made: from the views each planner plans by default."""
    own = recorded(rl, spec)
    others = [replace(own, views=default_views(make_planner(n))) for n in PLANNER_ORDER[:-1]]
    return judged_alike([own, *others])[0]


def _robot_program(
    part: Part, traj: Trajectory, context: PlanContext, spec: ScanSpec
) -> tuple[Trajectory, str, str, float, Program]:
    """The rl plan fitted to `DEMO_ROBOT` (the part placed, what the arm cannot fly given
    up), checked as `scanplan export` checks it and written in the arm's language: the fitted
    plan, the line saying so, the program, its largest read-back position error in m, and
    what the report says of it."""
    tcp = parse_pose_arg(DEMO_TCP)
    # Built once for the fit and the check: it samples the part's surface for the links.
    obstacles = obstacles_for(part, planned_cell(context, part), spec.sensor, spec.clearance_mm)
    fitted = fit_arm(part, traj, Arm(DEMO_ROBOT, tcp), context, obstacles)
    fitted_arm = Plan.of(fitted).arm
    assert fitted_arm is not None  # fit_arm records the arm
    record, T_base_part = fitted_arm.record, fitted_arm.T_base_part
    arm = get_robot(DEMO_ROBOT)
    checked = check_flyable(
        fitted, arm, T_base_part, tcp, part, planned_cell(context, part), spec.sensor, obstacles
    )
    if not checked.flyable:  # fit_arm gives up what the arm cannot fly: a bug if not
        raise ValueError(
            f"{DEMO_ROBOT} cannot fly the fitted plan: {checked.first_problem(fitted.swath)}"
        )
    options = ExportOptions(
        part_pose=T_base_part, tcp=tcp, scan=spec, joints_rad=checked.joints, arm=arm
    )
    text = export_program(fitted, DEMO_FORMAT, options)
    parsed, _ = parse_program(text, DEMO_FORMAT)
    # The program's targets are the fitted plan's poses thinned: compare each with its own.
    kept = plan_motion(fitted, options).source
    expected = T_base_part @ fitted.poses[kept]
    error_m = float(np.abs(parsed[:, :3, 3] - expected[:, :3, 3]).max()) / 1000.0
    given_up = sum(record["scanning_poses_given_up"].values())
    free, flown = free_and_flown(record) or (0.0, 0.0)
    unreachable = int((~np.isfinite(checked.joints).all(axis=1)).sum())
    cycle = program_cycle(Plan.of(fitted), options).total_s
    program = Program(PROGRAM_FILE, "RAPID, ABB", len(kept), cycle)
    line = (
        f"robot program: {DEMO_ROBOT} at --part-pose {record['part_pose']} --tcp {DEMO_TCP}, "
        f"{len(kept)} targets, {unreachable} unreachable, links clear -> "
        f"{PROGRAM_FILE}; the arm gave up {given_up} scanning poses (in-spec coverage "
        f"{free:.3f} without it, {flown:.3f} with it)"
    )
    return fitted, line, text, error_m, program


def _training_files(policy_dir: Path) -> tuple[Path | None, dict[str, Path]]:
    """The shipped policy's training log and curves (written by `scanplan train`): the log's
    path (None if the policy has none) and the curves by their name in the demo directory."""
    if not policy_dir.is_dir():
        return None, {}
    log = None
    curves: dict[str, Path] = {}
    for path in sorted(policy_dir.iterdir()):
        if path.suffix == ".png":
            curves[f"training_{path.name.removeprefix('training_')}"] = path
        elif path.suffix == ".csv":
            log = path
    return log, curves
