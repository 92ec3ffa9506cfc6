"""`scanplan defects`: the defects a plan would find. Seeded defects injected into the part,
the plan's scan of it simulated, hit/miss against size fitted as a POD curve (a50, a90,
a90/95), with the false calls the same plan makes on the defect-free part.
"""

from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from scanplan.cli.common import progress_bar, user_errors
from scanplan.cli.options import (
    PartArg,
    QuietOpt,
    SeedOpt,
    TrajectoryArg,
    UnitsOpt,
    bounded,
    within,
)
from scanplan.cli.planning import (
    EvaluateSchedulerOpt,
    EvaluateViewsOpt,
    counted,
    judged_context,
    trial_runner,
)
from scanplan.core.files import atomic_write_text
from scanplan.core.limits import DEFECT_SIZE_MM, K_SIGMA, MAX_DEFECTS, STEP_MM, check_count
from scanplan.core.quantities import DEFECT_K_SIGMA, DEFECT_MIN_POINTS, DEFECT_TYPE

TypeOpt = Annotated[str, typer.Option("--type", help="dent, bump, pit or scratch")]
SizesOpt = Annotated[
    str,
    typer.Option(
        help="LO:HI, the defects' depths in mm (a bump's height), spread evenly in log; "
        "the width follows the depth: dent and bump 10x (diameter), pit 4x, scratch 4x "
        "wide and 40x long"
    ),
]
DefectTrialsOpt = Annotated[
    int, typer.Option(help="trials (one defective part each)", callback=bounded(1, 10_000))
]
PerTrialOpt = Annotated[
    int,
    typer.Option(help="defects per trial, placed far apart", callback=bounded(1, 1000)),
]
KSigmaOpt = Annotated[
    float,
    typer.Option(
        "--k-sigma",
        help="a point is flagged beyond k·σ of the sensor noise there",
        callback=within(K_SIGMA),
    ),
]
MinPointsOpt = Annotated[
    int, typer.Option(help="flagged points a call needs", callback=bounded(1, 10_000))
]
DefectFreeOpt = Annotated[
    bool,
    typer.Option(
        "--defect-free/--no-defect-free",
        help="also scan the defect-free part with the plan: the false calls and the "
        "predicted detectability map (a full scan of the plan; off: faster)",
    ),
]
LinkOpt = Annotated[
    float | None,
    typer.Option(
        "--link",
        help="flagged points closer than this (mm) form one call; default: 1.5x the plan's "
        "median profile spacing (give the same value to compare plans under one rule)",
        callback=within(STEP_MM),
        show_default=False,
    ),
]
JsonOpt = Annotated[bool, typer.Option("--json", help="print one JSON object")]
DirOpt = Annotated[
    Path | None,
    typer.Option("-o", "--output", help="directory for pod.json, pod.png and defects.csv"),
]


def parse_sizes(text: str) -> tuple[float, float]:
    """'0.1:1.0' -> (0.1, 1.0) mm, each within `DEFECT_SIZE_MM`, LO <= HI."""
    lo_text, sep, hi_text = text.partition(":")
    try:
        lo = float(lo_text)
        hi = float(hi_text) if sep else lo
    except ValueError:
        raise ValueError(f"--sizes {text!r}: expected LO:HI in mm, e.g. 0.05:1.0") from None
    DEFECT_SIZE_MM.check(lo, "--sizes LO")
    DEFECT_SIZE_MM.check(hi, "--sizes HI")
    if lo > hi:
        raise ValueError(f"--sizes {text!r}: LO must be <= HI")
    return lo, hi


@user_errors
def defects_cmd(
    part: PartArg,
    trajectory: TrajectoryArg,
    kind: TypeOpt = DEFECT_TYPE,
    sizes: SizesOpt = "0.01:0.5",
    trials: DefectTrialsOpt = 16,
    per_trial: PerTrialOpt = 8,
    seed: SeedOpt = 0,
    k_sigma: KSigmaOpt = DEFECT_K_SIGMA,
    min_points: MinPointsOpt = DEFECT_MIN_POINTS,
    link: LinkOpt = None,
    as_json: JsonOpt = False,
    output: DirOpt = None,
    units: UnitsOpt = "mm",
    views: EvaluateViewsOpt = None,
    scheduler: EvaluateSchedulerOpt = None,
    defect_free: DefectFreeOpt = True,
    quiet: QuietOpt = False,
):
    """Inject seeded defects of one type at random places on the surface to inspect, simulate
    the plan's scan of each defective part, and fit the probability of detection against
    size (hit/miss, logistic on log size by maximum likelihood): a50, a90 and a90/95 (the
    95 % upper confidence bound on a90, delta method). A point is flagged where it departs
    from the nominal surface by more than k·σ of the sensor noise at it; flagged points
    form a call; a defect is found when a call lies on it. The false calls of the same plan
    on the defect-free part are reported beside."""
    # Deferred: the simulator loads trimesh, Embree and scipy; the report, matplotlib.
    from scanplan.cli.training import check_cluster
    from scanplan.core.trajectory import read_trajectory
    from scanplan.judging.detectability import PREDICTED, survey
    from scanplan.judging.detection import defect_run, defect_tasks, detector_for
    from scanplan.judging.evaluation import surface_samples
    from scanplan.sensor.defects import KINDS
    from scanplan.world.part import load_part

    start = time.perf_counter()
    if kind not in KINDS:
        raise ValueError(f"--type {kind!r}: use {', '.join(KINDS)}")
    lo, hi = parse_sizes(sizes)
    check_count(trials * per_trial, MAX_DEFECTS, "--trials x --per-trial defects")
    check_cluster(scheduler, None)
    traj = read_trajectory(trajectory)
    if not traj.scanning.any():
        raise ValueError(f"trajectory {trajectory} has no scanning pose")
    context, note = judged_context(traj, None, None, None, views)
    if note:
        typer.echo(note, err=True)
    the_part = load_part(part, units)
    spec = context.spec
    detector = detector_for(traj, spec.sensor, k_sigma=k_sigma, min_points=min_points)
    if link is not None:
        detector = replace(detector, link_mm=link)
    inspected = the_part.with_roi(context.roi)
    surface = surface_samples(inspected, spec.sensor, context, seed)
    tasks = defect_tasks(
        the_part, spec, traj, kind, (lo, hi), trials, per_trial, seed, context, detector, surface
    )
    with progress_bar("defect trials", quiet) as progress, trial_runner(scheduler, trials) as run:
        result = defect_run(tasks, counted(run, progress), seed)
    area = surface.area_mm2
    calls = detectability = None
    if defect_free:
        with progress_bar("defect-free scan", quiet) as progress:
            calls, detectability = survey(
                inspected, spec.sensor, traj.poses[traj.scanning], detector, surface, seed,
                progress=progress, swath=traj.swath[traj.scanning],
            )  # fmt: skip
    predicted: dict[str, float | None] = {}
    if detectability is not None and kind in PREDICTED:
        predicted = {
            f"a{round(100 * share)}_mm": detectability.predicted_a(kind, detector, share, seed)
            for share in (0.5, 0.9)
        }
    elapsed = time.perf_counter() - start
    data = {
        "part": the_part.name,
        "planner": traj.planner,
        **result.to_json_dict(),
        "false_calls": None if calls is None else calls.to_json_dict(),
        "predicted": (
            {**predicted, **detectability.to_json_dict()}
            if predicted and detectability is not None
            else None
        ),
        "time_s": elapsed,
    }
    if output is not None:
        from scanplan.judging.report.pod import plot_pod

        output.mkdir(parents=True, exist_ok=True)
        atomic_write_text(output / "pod.json", json.dumps(data, allow_nan=False, indent=1))
        rows = ["kind,x_mm,y_mm,z_mm,depth_mm,width_mm,length_mm,found,flagged_points,landed"]
        for d, h, f, n in zip(
            result.defects, result.hits, result.flagged_points, result.landed_points, strict=True
        ):
            x, y, z = d.centre_mm
            rows.append(
                f"{d.kind},{x:.3f},{y:.3f},{z:.3f},{d.depth_mm:.5g},{d.width_mm:.5g},"
                f"{d.length_mm:.5g},{int(h)},{int(f)},{int(n)}"
            )
        atomic_write_text(output / "defects.csv", "\n".join(rows) + "\n")
        plot_pod(result, output / "pod.png", f"{the_part.name}: {trajectory.name}")
        if predicted and detectability is not None:
            from scanplan.judging.report.pod import plot_detectability

            smallest = detectability.smallest_mm(kind, detector)
            table = np.column_stack([detectability.points_part, smallest])
            text = "x_mm,y_mm,z_mm,smallest_a90_mm\n" + "\n".join(
                ",".join(f"{v:.4g}" if i == 3 else f"{v:.3f}" for i, v in enumerate(row))
                for row in table
            )
            atomic_write_text(output / "detectability.csv", text + "\n")
            plot_detectability(
                detectability.points_part, smallest, kind,
                output / "detectability.png", f"{the_part.name}: {trajectory.name}",
            )  # fmt: skip
    if as_json:
        typer.echo(json.dumps(data, allow_nan=False))
        return
    typer.echo(
        f"{result.fit.line(kind)} | {len(result.defects)} defects over {trials} trials, depth "
        f"{lo:g}-{hi:g} mm, {result.seen_share:.1%} under the scan | call: > "
        f"{k_sigma:g}σ, >= {min_points} points within {detector.link_mm:.2f} mm"
        + (f" -> {output}" if output is not None else "")
    )
    if predicted:
        typer.echo(
            f"predicted from the defect-free scan's density and noise: a50 "
            f"{_mm(predicted['a50_mm'])}, a90 {_mm(predicted['a90_mm'])}"
        )
    if calls is None:
        typer.echo(f"no defect-free scan (--no-defect-free) | {elapsed:.1f} s")
        return
    typer.echo(
        f"false calls on the defect-free part: {calls.count} ({calls.per_m2:.2f} per m² over "
        f"{area / 1e6:.3f} m², {calls.flagged_points} of {calls.valid_points:,} points flagged)"
        f" | {elapsed:.1f} s"
    )


def _mm(value: float | None) -> str:
    return "not reached (too much of the surface unseen)" if value is None else f"{value:.3g} mm"
