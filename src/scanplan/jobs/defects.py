"""`defects`: the defects a plan would find. Seeded defects injected into the part, the
plan's scan of each defective part simulated, hit/miss against size fitted as a POD curve
(a50, a90, a90/95), with the false calls of the same plan on the defect-free part.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from scanplan.core.context import PlanContext
from scanplan.core.files import atomic_directory, atomic_write_text
from scanplan.core.limits import MAX_DEFECTS, check_count
from scanplan.core.plan import Plan
from scanplan.core.quantities import (
    DEFECT_K_SIGMA,
    DEFECT_MIN_POINTS,
    DEFECT_SIZES_MM,
    DEFECT_TRIALS,
    DEFECT_TYPE,
    DEFECTS_PER_TRIAL,
)
from scanplan.core.run import counted, task_runner
from scanplan.jobs.planned import ProgressBar, inspected, no_bar
from scanplan.judging.detectability import PREDICTED, Detectability
from scanplan.judging.detection import (
    DefectRun,
    Detector,
    FalseCalls,
    defect_run,
    defect_tasks,
    detector_for,
)
from scanplan.judging.evaluation import surface_samples
from scanplan.judging.survey import survey
from scanplan.sensor.defects import KINDS
from scanplan.world.cell import part_in_cell
from scanplan.world.part import Part

# What a defects folder holds: a folder with it may be replaced by a new run.
DEFECT_FILES = ("pod.json", "defects.csv", "pod.png")


@dataclass(frozen=True)
class DefectStudy:
    """What to inject and how to call a find: `trials` defective parts of `per_trial`
    defects each, depths (a bump's height) in `sizes_mm` spread evenly in log; a point is
    flagged beyond `k_sigma`·σ of the noise, a call needs `min_points` within `link_mm`
    (None: the plan's rule)."""

    kind: str = DEFECT_TYPE
    sizes_mm: tuple[float, float] = DEFECT_SIZES_MM
    trials: int = DEFECT_TRIALS
    per_trial: int = DEFECTS_PER_TRIAL
    seed: int = 0
    k_sigma: float = DEFECT_K_SIGMA
    min_points: int = DEFECT_MIN_POINTS
    link_mm: float | None = None
    scheduler: str | None = None
    defect_free: bool = True

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"--type {self.kind!r}: use {', '.join(KINDS)}")
        check_count(self.trials * self.per_trial, MAX_DEFECTS, "--trials x --per-trial defects")


@dataclass(frozen=True)
class DefectOutcome:
    """A study's result: the injected run, the call rule, the defect-free scan's false calls
    and detectability (None with `defect_free` off), the predicted a50/a90, and its data as
    `--json` prints it."""

    result: DefectRun
    detector: Detector
    calls: FalseCalls | None
    detectability: Detectability | None
    predicted: dict[str, float | None]
    area_mm2: float
    data: dict[str, Any]


def run_defects(
    plan: Plan, part: Part, context: PlanContext, study: DefectStudy, bar: ProgressBar = no_bar
) -> DefectOutcome:
    """Run `study` on `plan` over `part`, judged by `context`."""
    start = time.perf_counter()
    traj, spec = plan.traj, context.spec
    if not traj.scanning.any():
        raise ValueError(f"{plan.where} has no scanning pose")
    detector = detector_for(traj, spec.sensor, k_sigma=study.k_sigma, min_points=study.min_points)
    if study.link_mm is not None:
        detector = replace(detector, link_mm=study.link_mm)
    inspected_part = inspected(plan, part, context)
    surface = surface_samples(inspected_part, spec.sensor, context, study.seed)
    tasks = defect_tasks(
        part, spec, traj, study.kind, study.sizes_mm, study.trials, study.per_trial,
        study.seed, context, detector, surface,
    )  # fmt: skip
    with bar("defect trials") as progress, task_runner(study.scheduler, study.trials) as run:
        result = defect_run(tasks, counted(run, progress), study.seed)
    calls = detectability = None
    if study.defect_free:
        with bar("defect-free scan") as progress:
            calls, detectability = survey(
                part_in_cell(context, inspected_part), spec.sensor, traj.poses[traj.scanning],
                detector, surface, study.seed, progress=progress, swath=traj.swath[traj.scanning],
            )  # fmt: skip
    predicted: dict[str, float | None] = {}
    if detectability is not None and study.kind in PREDICTED:
        predicted = {
            f"a{round(100 * share)}_mm": detectability.predicted_a(
                study.kind, detector, share, study.seed
            )
            for share in (0.5, 0.9)
        }
    data = {
        "part": part.name,
        "planner": traj.planner,
        **result.to_json_dict(),
        "false_calls": None if calls is None else calls.to_json_dict(),
        "predicted": (
            {**predicted, **detectability.to_json_dict()}
            if predicted and detectability is not None
            else None
        ),
        "time_s": time.perf_counter() - start,
    }
    return DefectOutcome(result, detector, calls, detectability, predicted, surface.area_mm2, data)


def write_defects(output: Path, outcome: DefectOutcome, study: DefectStudy, title: str) -> None:
    """The folder of a study, written whole or not at all: pod.json, defects.csv, pod.png
    and, where predicted, the detectability map."""
    # Deferred: the plots load matplotlib.
    from scanplan.judging.report.pod import plot_detectability, plot_pod

    def is_defects(path: Path) -> bool:
        return (path / "pod.json").exists()

    result = outcome.result
    with atomic_directory(output, is_defects) as tmp:
        atomic_write_text(tmp / "pod.json", json.dumps(outcome.data, allow_nan=False, indent=1))
        rows = ["kind,x_mm,y_mm,z_mm,depth_mm,width_mm,length_mm,found,flagged_points,landed"]
        for d, h, f, n in zip(
            result.defects, result.hits, result.flagged_points, result.landed_points, strict=True
        ):
            x, y, z = d.centre_mm
            rows.append(
                f"{d.kind},{x:.3f},{y:.3f},{z:.3f},{d.depth_mm:.5g},{d.width_mm:.5g},"
                f"{d.length_mm:.5g},{int(h)},{int(f)},{int(n)}"
            )
        atomic_write_text(tmp / "defects.csv", "\n".join(rows) + "\n")
        plot_pod(result, tmp / "pod.png", title)
        found = outcome.detectability
        if outcome.predicted and found is not None:
            smallest = found.smallest_mm(study.kind, outcome.detector)
            table = np.column_stack([found.points_part, smallest])
            text = "x_mm,y_mm,z_mm,smallest_a90_mm\n" + "\n".join(
                ",".join(f"{v:.4g}" if i == 3 else f"{v:.3f}" for i, v in enumerate(row))
                for row in table
            )
            atomic_write_text(tmp / "detectability.csv", text + "\n")
            plot_detectability(
                found.points_part, smallest, study.kind, tmp / "detectability.png", title
            )


def defects_lines(outcome: DefectOutcome, study: DefectStudy, output: Path | None) -> list[str]:
    """The study's result in a few lines: the POD fit, the prediction, the false calls."""
    result, calls, predicted = outcome.result, outcome.calls, outcome.predicted
    lo, hi = study.sizes_mm
    lines = [
        f"{result.fit.line(study.kind)} | {len(result.defects)} defects over {study.trials} "
        f"trials, depth {lo:g}-{hi:g} mm, {result.seen_share:.1%} under the scan | call: > "
        f"{study.k_sigma:g}σ, >= {study.min_points} points within "
        f"{outcome.detector.link_mm:.2f} mm" + (f" -> {output}" if output is not None else "")
    ]
    if predicted:
        lines.append(
            f"predicted from the defect-free scan's density and noise: a50 "
            f"{_mm(predicted['a50_mm'])}, a90 {_mm(predicted['a90_mm'])}"
        )
    elapsed = outcome.data["time_s"]
    if calls is None:
        lines.append(f"no defect-free scan (--no-defect-free) | {elapsed:.1f} s")
        return lines
    lines.append(
        f"false calls on the defect-free part: {calls.count} ({calls.per_m2:.2f} per m² over "
        f"{outcome.area_mm2 / 1e6:.3f} m², {calls.flagged_points} of {calls.valid_points:,} "
        f"points flagged) | {elapsed:.1f} s"
    )
    return lines


def _mm(value: float | None) -> str:
    return "not reached (too much of the surface unseen)" if value is None else f"{value:.3g} mm"
