"""`scanplan demo`, the main job (SPEC §9): the door, the three planners, the numbers, the
pictures, the report and a URScript program, in a few minutes on 2 cores.

Everything the demo shows comes from the library calls a user makes from the command line
(plan_path, evaluate, write_report, export_program); nothing is demo-only.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scanplan.context import judged_alike, recorded
from scanplan.export import ExportOptions, export_program, parse_program
from scanplan.export.common import plan_motion
from scanplan.metrics import Metrics, evaluate
from scanplan.part import Part, load_part
from scanplan.pipeline import plan_views
from scanplan.planners import Planner, make_planner
from scanplan.quantities import ScanSpec
from scanplan.report import Evaluated, write_report
from scanplan.trajectory import Trajectory, to_csv_text

PLANNER_ORDER = ("fixed", "geometric", "rl")


@dataclass(frozen=True)
class DemoResult:
    out_dir: Path
    metrics: dict[str, Metrics]
    trajectories: dict[str, Trajectory]
    report: Path
    program: Path
    program_error_m: float
    seconds: float


def run_demo(
    out_dir: Path,
    part_name: str = "door",
    units: str = "mm",
    spec: ScanSpec | None = None,
    points_per_profile: int | None = 1024,
    seed: int = 0,
    step: Callable[[str], None] = lambda message: None,
    roi: str | None = None,
) -> DemoResult:
    """Plan, evaluate, draw, report and export. `step` is told what is starting (progress);
    `roi`: a region of interest (`part.parse_roi`) that planning and coverage keep to.

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
    contexts = judged_alike([recorded(t, spec) for t in trajectories.values()])
    for (name, traj), context in zip(trajectories.items(), contexts, strict=True):
        step(f"evaluating {name} ({int(traj.scanning.sum())} profiles, {context.surface} surface)")
        # The cycle timed as the exported program flies it: between its thinned targets.
        motion = plan_motion(traj, ExportOptions(scan=spec))
        metrics[name] = evaluate(
            part,
            spec,
            traj,
            seed,
            points_per_profile,
            context=context,
            targets=motion.source,
            blended=motion.blend_mm > 0,
        )

    step("writing the URScript program")
    best = trajectories["rl"]
    text = export_program(best, "urscript", ExportOptions(scan=spec))
    files["scan_rl.script"] = text
    parsed, _ = parse_program(text, "urscript")
    # The program's targets are the plan's poses thinned: compare each with its own.
    kept = plan_motion(best, ExportOptions(scan=spec)).source
    error_m = float(np.abs(parsed[:, :3, 3] - best.poses[kept, :3, 3]).max()) / 1000.0

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
    )
    return DemoResult(
        out_dir,
        metrics,
        trajectories,
        report,
        out_dir / "scan_rl.script",
        error_m,
        time.perf_counter() - start,
    )


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
