"""`scanplan evaluate` and `scan`: a plan's scan simulated on its part, judged (in-spec
coverage, errors, cycle time, robustness) or written as a point cloud.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from scanplan.cli.common import EXIT_FAILED_REQUIREMENT, progress_bar, user_errors
from scanplan.cli.options import (
    POINTS_CHECK,
    FixtureOpt,
    Full3dOpt,
    PartAndPlanArg,
    QuietOpt,
    RequireOpt,
    RoiOpt,
    SeedOpt,
    TableOpt,
    ToleranceOpt,
    bounded,
    parse_tolerance,
    part_and_plan,
    surface_choice,
)
from scanplan.cli.training import check_cluster
from scanplan.core.quantities import PERTURB_TRIALS
from scanplan.core.sensor_spec import DEMO_POINTS, SensorSpec

PlanUnitsOpt = Annotated[
    str | None,
    typer.Option(
        "--units",
        metavar="UNIT",
        help="units of the part's mesh file: mm, m or in; default: those the plan was made with",
        show_default=False,
    ),
]
OtherPartOpt = Annotated[
    bool,
    typer.Option(
        "--other-part",
        help="use PART even though it is not the part the plan was made for (said in a note); "
        "without it, another part (or the same file in other units) is refused",
    ),
]
# ---- scan ---------------------------------------------------------------------------------
CloudOutOpt = Annotated[
    Path,
    typer.Option(
        "-o",
        "--output",
        metavar="FILE",
        help="output file: the point cloud (.ply), in the part's frame, mm",
    ),
]
NoNoiseOpt = Annotated[bool, typer.Option("--no-noise", help="switch noise off")]
ScanPointsOpt = Annotated[
    int | None,
    typer.Option(
        "--points",
        help=f"pixel columns per profile, 2 to {SensorSpec.MAX_POINTS} (same line width); "
        "default: the sensor's",
        callback=POINTS_CHECK,
        show_default=False,
    ),
]
MaxPointsOpt = Annotated[
    int | None,
    typer.Option(
        "--max-points",
        help="write a uniform random sample (seeded) of at most N valid points",
        callback=bounded(1, None),
        show_default=False,
    ),
]


ScanSensorOpt = Annotated[
    str | None,
    typer.Option(
        "--sensor",
        help="sensor preset name or TOML/YAML datasheet file; default: the plan's",
        show_default=False,
    ),
]


@user_errors
def scan_cmd(
    paths: PartAndPlanArg,
    output: CloudOutOpt,
    sensor: ScanSensorOpt = None,
    units: PlanUnitsOpt = None,
    seed: SeedOpt = 0,
    no_noise: NoNoiseOpt = False,
    quiet: QuietOpt = False,
    roi: RoiOpt = None,
    points: ScanPointsOpt = None,
    max_points: MaxPointsOpt = None,
    other_part: OtherPartOpt = False,
):
    """Simulate the scan of a plan on its part; write the point cloud (PLY) with error
    fields. The full cloud of a large part runs to GB: its size is printed first, and
    --points or --max-points write fewer."""
    # Deferred: the simulator loads trimesh and Embree (seconds), which --help need not.
    from scanplan.core.plan import read_plan
    from scanplan.core.sensor_files import load_sensor
    from scanplan.jobs.planned import planned_part
    from scanplan.jobs.scan import megabytes, scan_plan, scan_size_line

    if output.suffix.lower() != ".ply":
        raise ValueError(f"output {output} must be a .ply file")
    part, trajectory = part_and_plan(paths)
    plan = read_plan(trajectory)
    spec = plan.spec.sensor if sensor is None else load_sensor(sensor)
    if no_noise:
        spec = spec.without_noise()
    if points is not None:
        spec = spec.with_points(points)
    say = lambda text: typer.echo(text, err=True)  # noqa: E731
    the_part = planned_part(plan, part, units, other_part=other_part, say=say).with_roi(roi)
    if not plan.traj.scanning.any():
        raise ValueError(f"trajectory {trajectory} has no scanning pose")
    # Before scanning (stdout: stderr carries only an error's one line).
    typer.echo(scan_size_line(plan, spec, max_points))
    with progress_bar("scanning", quiet) as progress:
        cloud = scan_plan(plan, the_part, spec, output, seed, max_points, progress)
    typer.echo(
        f"{len(cloud.points_part)} points from {int(plan.traj.scanning.sum())} profiles -> "
        f"{output} ({megabytes(output.stat().st_size)})"
    )


# ---- evaluate -----------------------------------------------------------------------------
JsonOpt = Annotated[bool, typer.Option("--json", help="print one JSON object")]
ReportDirOpt = Annotated[
    Path | None,
    typer.Option(
        "-o",
        "--output",
        metavar="FOLDER",
        help="output folder: the maps (PNG), metrics.json, metrics.md and report.html",
    ),
]
EvaluatePointsOpt = Annotated[
    int | None,
    typer.Option(
        "--points",
        help="simulate N of the sensor's pixel columns across the same line (faster; the "
        f"demo uses {DEMO_POINTS}), 2 to {SensorSpec.MAX_POINTS}; default: all of the sensor's "
        f"({SensorSpec().points_per_profile} for the default sensor)",
        show_default=False,
        callback=POINTS_CHECK,
    ),
]
SurfaceOpt = Annotated[
    str | None,
    typer.Option(
        "--surface",
        metavar="NAME",
        help="the surface to judge: top (what faces up) or hemisphere (what the upper "
        "hemisphere sees, walls included); default: the plan's",
        show_default=False,
    ),
]
# The old name of --surface (plan's --views chooses how to plan): still read, with a warning.
OldViewsOpt = Annotated[str | None, typer.Option("--views", hidden=True, show_default=False)]
EvaluateSensorOpt = Annotated[
    str | None,
    typer.Option(
        "--sensor",
        help="sensor preset name or TOML/YAML datasheet file; default: the plan's",
        show_default=False,
    ),
]

PerturbOpt = Annotated[
    str | None,
    typer.Option(
        help="also replay the plan on perturbed parts, e.g. "
        "'place:2mm,1deg;warp:1mm@200mm;scale:0.1%;path:0.1mm,0.05deg' (each a standard "
        "deviation; ±2mm: uniform bounds): placement error, as-built deviation (RMS along the "
        "normal @ wavelength), scale, robot path error",
        show_default=False,
    ),
]
TrialsOpt = Annotated[
    int, typer.Option(help="perturbed trials with --perturb", callback=bounded(1, 10_000))
]
EvaluateSchedulerOpt = Annotated[
    str | None,
    typer.Option(
        "--scheduler",
        help="run the trials on the Dask scheduler tcp://HOST:8786 (default: every core here)",
        show_default=False,
    ),
]
ClosedLoopOpt = Annotated[
    bool,
    typer.Option(
        "--closed-loop",
        help="with --perturb, a feedback or rl plan's controller runs again on each perturbed "
        "part, acting on its profiles as on a cell; in a plan fitted to an arm, its "
        "corrections kept within the arm's reach (default: the plan is replayed)",
    ),
]
EvaluatePolicyOpt = Annotated[
    str | None,
    typer.Option(
        "--policy",
        help="--closed-loop of an rl plan: the policy it was planned with (default: the "
        "shipped one, v1 if the plan rolls)",
        show_default=False,
    ),
]


@user_errors
def evaluate_cmd(
    paths: PartAndPlanArg,
    as_json: JsonOpt = False,
    output: ReportDirOpt = None,
    sensor: EvaluateSensorOpt = None,
    units: PlanUnitsOpt = None,
    points: EvaluatePointsOpt = None,
    seed: SeedOpt = 0,
    tolerance: ToleranceOpt = None,
    quiet: QuietOpt = False,
    roi: RoiOpt = None,
    surface: SurfaceOpt = None,
    views: OldViewsOpt = None,
    table: TableOpt = None,
    fixture: FixtureOpt = None,
    full_3d: Full3dOpt = False,
    perturb: PerturbOpt = None,
    trials: TrialsOpt = PERTURB_TRIALS,
    scheduler: EvaluateSchedulerOpt = None,
    closed_loop: ClosedLoopOpt = False,
    policy: EvaluatePolicyOpt = None,
    other_part: OtherPartOpt = False,
    require: RequireOpt = None,
):
    """Simulate the scan of a plan on its part and report its quality, judged as the plan
    file records it (part and units, sensor, tolerance, region of interest, surface) unless
    an option says otherwise. With --perturb, also how that in-spec coverage holds on seeded
    perturbed parts (mean, p5 - the coverage 95 % of the trials reach - and worst) and which
    surface is fragile: the plan replayed as planned, or with --closed-loop its controller
    (feedback, rl) acting on the profiles of each perturbed part."""
    # Deferred: judging loads trimesh, Embree and FCL (seconds), which --help need not.
    from scanplan.core.plan import read_plan
    from scanplan.jobs.evaluate import (
        Trials,
        check_trials,
        evaluate_plan,
        judged_part,
        metrics_line,
        run_trials,
        write_evaluation,
    )
    from scanplan.jobs.planned import judged_context
    from scanplan.judging.verdict import figures_of, judge, parse_requirements, verdict_lines
    from scanplan.sensor.perturb import Perturbation

    criteria = () if require is None else parse_requirements(require)
    model = Perturbation.parse(perturb) if perturb is not None else None
    if model is None and scheduler is not None:
        raise ValueError("--scheduler runs --perturb's trials: give --perturb too")
    if model is None and closed_loop:
        raise ValueError("--closed-loop runs --perturb's trials in closed loop: give --perturb")
    if policy is not None and not closed_loop:
        raise ValueError("--policy is the rl plan's policy for --closed-loop: give --closed-loop")
    check_cluster(scheduler, None)
    if output is not None and str(output) in ("", "."):
        raise ValueError(f"-o {str(output)!r}: give the report's folder name")
    part, trajectory = part_and_plan(paths)
    plan = read_plan(trajectory)
    arm_record = plan.arm.record if plan.arm is not None else None
    check_evaluate_require(criteria, model is not None, arm_record is not None)
    views, warning = surface_choice(surface, views, "evaluate")
    context, note = judged_context(
        plan, sensor, parse_tolerance(tolerance), roi, views, table, fixture
    )
    say = lambda text: typer.echo(text, err=True)  # noqa: E731
    the_part = judged_part(plan, part, units, context, other_part, say)
    run = None if model is None else Trials(model, trials, scheduler, closed_loop, policy)
    check_trials(plan, context, run)
    with progress_bar("evaluating", quiet) as progress:
        metrics = evaluate_plan(plan, the_part, context, seed, points, progress)
    robust = None
    if run is not None:
        robust = run_trials(
            plan, the_part, context, run, seed, points, lambda label: progress_bar(label, quiet)
        )
    verdicts = judge(criteria, figures_of(metrics, robust, arm_record))
    if output is not None:
        write_evaluation(output, plan, the_part, context, metrics, robust, full_3d, verdicts)
    data = metrics.to_json_dict()
    if robust is not None:
        data["robustness"] = {"nominal": metrics.in_spec_coverage, **robust.to_json_dict()}
    if verdicts:
        data["verdicts"] = [v.to_json_dict() for v in verdicts]
        data["pass"] = all(v.passed for v in verdicts)
    for line in (warning, note):  # after the work: a command that fails says one line, its error
        if line:
            say(line)
    if as_json:
        typer.echo(json.dumps(data, allow_nan=False))
    else:
        typer.echo(metrics_line(metrics, data) + (f" -> {output}" if output is not None else ""))
        if metrics.cycle is not None:
            typer.echo(metrics.cycle.line())
        if robust is not None:
            typer.echo(robust.line(metrics.in_spec_coverage))
        for line in verdict_lines(verdicts):
            typer.echo(line)
    if any(not v.passed for v in verdicts):
        raise typer.Exit(EXIT_FAILED_REQUIREMENT)


def check_evaluate_require(criteria: tuple, perturbed: bool, has_arm: bool) -> None:
    """A criterion this evaluation will not measure is named before any work."""
    from scanplan.judging.verdict import check_available

    missing = {"pod-a90": "is measured by compare --defects or the defects command"}
    if not perturbed:
        missing |= dict.fromkeys(("p5", "worst"), "needs --perturb")
    if not has_arm:
        missing["arm-cost"] = "needs a plan made with --robot"
    check_available(criteria, missing)
