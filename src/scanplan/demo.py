"""`scanplan demo`, the main job (SPEC §9): the door, the three planners, the numbers, the
pictures, the report and a URScript program, in a few minutes on 2 cores.

Everything the demo shows comes from the library calls a user makes from the command line
(plan_path, evaluate, plot_*, write_html_report, export_program); nothing is demo-only.
"""

from __future__ import annotations

import json
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scanplan.metrics import Metrics, evaluate
from scanplan.part import Part, load_part
from scanplan.planners import Planner, make_planner, plan_path
from scanplan.quantities import ScanSpec
from scanplan.report.html import PlannerResult, write_html_report
from scanplan.swaths import plan_swaths
from scanplan.trajectory import Trajectory, atomic_write_text, write_csv

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
) -> DemoResult:
    """Plan, evaluate, draw, report and export. `step` is told what is starting (progress)."""
    from scanplan.export import ExportOptions, export_program, parse_program
    from scanplan.report.maps import plot_comparison, plot_error_maps

    start = time.perf_counter()
    spec = spec or ScanSpec()
    sensor = spec.sensor
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    step(f"loading part {part_name}")
    part: Part = load_part(part_name, units)
    swaths = plan_swaths(part, sensor)

    metrics: dict[str, Metrics] = {}
    trajectories: dict[str, Trajectory] = {}
    for name in PLANNER_ORDER:
        planner: Planner = make_planner(name)
        step(f"planning {name} ({len(swaths)} passes)")
        traj = plan_path(part, spec, planner, swaths)
        trajectories[name] = traj
        write_csv(traj, out_dir / f"trajectory_{name}.csv")
        step(f"evaluating {name} ({int(traj.scanning.sum())} profiles)")
        metrics[name] = evaluate(part, spec, traj, seed=seed, points_per_profile=points_per_profile)
        plot_error_maps(metrics[name], out_dir / name, planner=name, part=part.name)

    step("drawing maps")
    sources = [(name, m) for name, m in metrics.items()]
    pictures = [
        plot_comparison(sources, "distance", out_dir / "distance_error_maps.png", part=part.name),
        plot_comparison(
            sources, "orientation", out_dir / "orientation_error_maps.png", part=part.name
        ),
    ]
    from scanplan.planners.rl import DEFAULT_POLICY

    training_log = _copy_training_curves(DEFAULT_POLICY, out_dir)
    pictures += sorted(out_dir.glob("training_*.png"))

    json_metrics = {name: m.to_json_dict() for name, m in metrics.items()}
    atomic_write_text(out_dir / "metrics.json", json.dumps(json_metrics, indent=1) + "\n")

    step("writing the HTML report")
    results = [
        PlannerResult(name, trajectories[name], cloud, json_metrics[name])
        for name, m in metrics.items()
        if (cloud := m.cloud) is not None
    ]
    fan = f"{points_per_profile} of {sensor.points_per_profile}" if points_per_profile else "all"
    report = out_dir / "report.html"
    write_html_report(
        report,
        part,
        results,
        sensor.name,
        training_log=training_log,
        pictures=pictures,
        notes=[f"Evaluated with {fan} pixel columns per profile, noise seed {seed}."],
    )

    step("writing the URScript program")
    best = trajectories["rl"]
    options = ExportOptions(scan=spec)
    program = out_dir / "scan_rl.script"
    text = export_program(best, "urscript", options)
    atomic_write_text(program, text)
    parsed, _ = parse_program(text, "urscript")
    error_m = float(np.abs(parsed[:, :3, 3] - best.poses[:, :3, 3]).max()) / 1000.0
    return DemoResult(
        out_dir, metrics, trajectories, report, program, error_m, time.perf_counter() - start
    )


def _copy_training_curves(policy_dir: Path, out_dir: Path) -> Path | None:
    """The shipped policy's training log and curves (written by `scanplan train`), next to
    the demo's outputs; the log's path, or None if the policy has none."""
    if not policy_dir.is_dir():
        return None
    log = None
    for path in sorted(policy_dir.iterdir()):
        if path.suffix == ".png":
            shutil.copy(path, out_dir / f"training_{path.name.removeprefix('training_')}")
        elif path.suffix == ".csv":
            log = out_dir / "training_log.csv"
            shutil.copy(path, log)
    return log
