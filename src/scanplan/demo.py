"""`scanplan demo`, the main job (SPEC §9): the door, the three planners, the numbers, the
pictures, the report and a robot program for a real cell, in a few minutes on 2 cores.

Everything the demo shows comes from the library calls a user makes from the command line
(plan_views, evaluate, write_report, fit_arm, check_flyable, export_program); nothing is
demo-only.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scanplan.context import PlanContext, judged_alike, recorded
from scanplan.export import ExportOptions, export_program, parse_pose_arg, parse_program
from scanplan.export.common import plan_motion
from scanplan.metrics import Metrics
from scanplan.metrics.detectability import evaluate_detectable
from scanplan.part import Part, load_part
from scanplan.pipeline import Arm, fit_arm, plan_views
from scanplan.planners import Planner, make_planner
from scanplan.quantities import ScanSpec
from scanplan.report import Evaluated, write_report
from scanplan.robot import get_robot
from scanplan.robot.flyable import check_flyable
from scanplan.robot.links import obstacles_for
from scanplan.sensor import DEMO_POINTS
from scanplan.trajectory import Trajectory, dumps_json, to_csv_text, to_json_dict

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
    sensor = spec.sensor
    out_dir = Path(out_dir)
    step(f"loading part {part_name}")
    part: Part = load_part(part_name, units)

    metrics: dict[str, Metrics] = {}
    trajectories: dict[str, Trajectory] = {}
    files: dict[str, str | bytes | Path] = {}
    for name in PLANNER_ORDER:
        planner: Planner = make_planner(name)
        step(f"planning {name}")
        # Each planner with its own default views.
        plans, traj = plan_views(part, spec, planner, roi=roi)
        passes = sum(p.passes for p in plans)
        step(f"planned {name}: {len(plans)} view{'s' * (len(plans) > 1)}, {passes} passes")
        trajectories[name] = traj
        files[f"trajectory_{name}.csv"] = to_csv_text(traj)
    # All judged on one surface: a table of figures over different surfaces compares nothing.
    judged = judged_alike([recorded(t, spec) for t in trajectories.values()])
    contexts = dict(zip(trajectories, judged, strict=True))
    for (name, traj), context in zip(trajectories.items(), contexts.values(), strict=True):
        step(f"evaluating {name} ({int(traj.scanning.sum())} profiles, {context.surface} surface)")
        # The cycle timed as the exported program flies it: between its thinned targets.
        motion = plan_motion(traj, ExportOptions(scan=spec))
        metrics[name] = evaluate_detectable(
            part,
            spec,
            traj,
            seed,
            points_per_profile,
            context=context,
            targets=motion.source,
            blended=motion.blend_mm > 0,
        )

    step(f"fitting the rl plan to an {DEMO_ROBOT} (placing the part)")
    fit_started = time.perf_counter()
    fitted, robot_line, text, error_m = _robot_program(
        part, trajectories["rl"], contexts["rl"], spec
    )
    files[PROGRAM_FILE] = text
    # The fitted plan records the arm, part pose and TCP: `scanplan export` takes it as is.
    files[FITTED_FILE] = dumps_json(to_json_dict(fitted), indent=1)
    step(f"{robot_line} ({time.perf_counter() - fit_started:.0f} s)")

    # Deferred: the rl planner's module loads torch.
    from scanplan.planners.rl import DEFAULT_POLICY

    training_log, curves = _training_files(DEFAULT_POLICY)
    files.update(curves)
    if training_log is not None:
        files["training_log.csv"] = training_log
    step("drawing the maps and writing the report")
    fan = f"{points_per_profile} of {sensor.points_per_profile}" if points_per_profile else "all"
    report = write_report(
        out_dir,
        part.with_roi(roi),
        [Evaluated(name, trajectories[name], m) for name, m in metrics.items()],
        spec,
        pictures=list(curves.values()),
        notes=[f"Evaluated with {fan} pixel columns per profile, noise seed {seed}."],
        training_log=training_log,
        files=files,
        title=f"{part.name}: scan quality by planner",
        full_3d=full_3d,
    )
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


def _robot_program(
    part: Part, traj: Trajectory, context: PlanContext, spec: ScanSpec
) -> tuple[Trajectory, str, str, float]:
    """The rl plan fitted to `DEMO_ROBOT` (the part placed, what the arm cannot fly given
    up), checked as `scanplan export` checks it and written in the arm's language: (the line
    saying so, the program, its largest read-back position error in m), after the fitted plan."""
    tcp = parse_pose_arg(DEMO_TCP)
    # Built once for the fit and the check: it samples the part's surface for the links.
    obstacles = obstacles_for(part, context.cell(part), spec.sensor, spec.clearance_mm)
    fitted = fit_arm(part, traj, Arm(DEMO_ROBOT, tcp), context, obstacles)
    record = fitted.meta["robot"]
    T_base_part = np.asarray(record["T_base_part"], dtype=np.float64)
    arm = get_robot(DEMO_ROBOT)
    checked = check_flyable(
        fitted, arm, T_base_part, tcp, part, context.cell(part), spec.sensor, obstacles
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
    unreachable = int((~np.isfinite(checked.joints).all(axis=1)).sum())
    line = (
        f"robot program: {DEMO_ROBOT} at --part-pose {record['part_pose']} --tcp {DEMO_TCP}, "
        f"{len(kept)} targets, {unreachable} unreachable, links clear -> "
        f"{PROGRAM_FILE}; the arm gave up {given_up} scanning poses (in-spec coverage "
        f"{record['in_spec_without_robot']:.3f} without it, {record['in_spec']:.3f} with it)"
    )
    return fitted, line, text, error_m


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
