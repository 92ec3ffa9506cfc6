"""`scanplan compare`: parts (and planners, views) side by side in one table, hardest to
scan first, with verdicts; on the terminal and as Markdown, CSV, JSON or an HTML page.
"""

from __future__ import annotations

import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer

from scanplan.cli.common import EXIT_FAILED_REQUIREMENT, user_errors
from scanplan.cli.options import (
    POINTS_CHECK,
    PartPoseOpt,
    PlanTcpOpt,
    QuietOpt,
    RequireOpt,
    RoiOpt,
    SeedOpt,
    SensorOpt,
    TableOpt,
    ToleranceOpt,
    UnitsOpt,
    bounded,
    scan_spec,
)
from scanplan.cli.plan import PlanRobotOpt
from scanplan.core.quantities import DEFECT_TRIALS, PERTURB_TRIALS
from scanplan.core.sensor_spec import DEFAULT_SENSOR

PartsArg = Annotated[
    list[str],
    typer.Argument(
        help="parts to compare: built-in names, mesh or STEP files (PATH:UNITS gives a file's "
        "units, e.g. bracket.stl:in), folders of them, or .txt lists of them with one "
        "'PATH [UNITS]' a line",
        show_default=False,
    ),
]
CompareOutOpt = Annotated[
    Path | None,
    typer.Option(
        "-o",
        "--output",
        help="output file: the table also written there, its format from the extension (.md, .csv, "
        ".json, .html, .txt) unless --format says",
        show_default=False,
    ),
]
FormatOpt = Annotated[
    str | None,
    typer.Option(
        "--format",
        help="format of -o: text, md, csv, json or html; default: from -o's extension",
        show_default=False,
    ),
]
PlannersOpt = Annotated[
    str,
    typer.Option(
        "--planner",
        help="planner, or several comma-separated (a row each): fixed, feedback, geometric, rl",
    ),
]
CompareViewsOpt = Annotated[
    str | None,
    typer.Option(
        "--views",
        help="how the plans choose views, or several comma-separated (a row each): top or "
        "auto; default: each planner's own",
        show_default=False,
    ),
]
ComparePointsOpt = Annotated[
    int | None,
    typer.Option(
        "--points",
        help="judge with N pixel columns a profile (faster, as evaluate --points); default: "
        "the sensor's, as evaluate",
        callback=POINTS_CHECK,
        show_default=False,
    ),
]
ComparePerturbOpt = Annotated[
    str | None,
    typer.Option(
        "--perturb",
        help="also replay each plan on perturbed parts (as evaluate --perturb, e.g. "
        "'place:2mm,1deg;warp:1mm@200mm') for the p5 column (the JSON also holds the worst trial)",
        show_default=False,
    ),
]
CompareTrialsOpt = Annotated[
    int,
    typer.Option("--trials", help="perturbed trials with --perturb", callback=bounded(1, 10_000)),
]
DefectsOpt = Annotated[
    bool,
    typer.Option(
        "--defects",
        help="also inject dents into each part and fit the probability of finding them (as "
        "the defects command, with its defaults) for the column 'dent a90 (trials)'",
    ),
]
DefectTrialsOpt = Annotated[
    int,
    typer.Option(
        "--defect-trials",
        help="defective parts per plan with --defects",
        callback=bounded(1, 10_000),
    ),
]
PlansOpt = Annotated[
    Path | None,
    typer.Option(
        "--plans",
        help="keep the plan files in this folder (PART-PLANNER-VIEWS.json) for evaluate, "
        "export and view; default: they are removed",
        show_default=False,
    ),
]


@user_errors
def compare_cmd(
    parts: PartsArg,
    output: CompareOutOpt = None,
    output_format: FormatOpt = None,
    planner: PlannersOpt = "geometric",
    views: CompareViewsOpt = None,
    sensor: SensorOpt = DEFAULT_SENSOR,
    tolerance: ToleranceOpt = None,
    units: UnitsOpt = "mm",
    roi: RoiOpt = None,
    table: TableOpt = None,
    robot: PlanRobotOpt = None,
    tcp: PlanTcpOpt = None,
    part_pose: PartPoseOpt = None,
    points: ComparePointsOpt = None,
    seed: SeedOpt = 0,
    perturb: ComparePerturbOpt = None,
    trials: CompareTrialsOpt = PERTURB_TRIALS,
    defects: DefectsOpt = False,
    defect_trials: DefectTrialsOpt = DEFECT_TRIALS,
    require: RequireOpt = None,
    plans: PlansOpt = None,
    quiet: QuietOpt = False,
):
    """Compare parts, planners and views in one table, hardest to scan first: each part is
    planned as plan plans it and judged as evaluate judges it (in-spec coverage, visibility
    ceiling, cycle time, the dent depth found 90 % of the time), with --robot flown by that
    arm (what the arm cost), with --perturb perturbed (p5), with --defects searched for
    injected dents. A part that fails is one error row (exit 1); a row that fails --require
    exits 3."""
    # Deferred: the jobs load trimesh, Embree and FCL (seconds), which --help need not.
    from scanplan.core.files import atomic_write_text
    from scanplan.jobs.compare import Comparison, compare, failed_rows
    from scanplan.jobs.defects import DefectStudy
    from scanplan.jobs.evaluate import Trials
    from scanplan.jobs.plan import PlanJob
    from scanplan.judging.report.comparison import FORMATS, hardest_first, render, to_text
    from scanplan.judging.verdict import parse_requirements
    from scanplan.sensor.perturb import Perturbation
    from scanplan.world.part_list import expand_parts

    fmt = output_format
    if output is not None and fmt is None:
        suffix = output.suffix.lower().lstrip(".")
        fmt = {"txt": "text", "markdown": "md", "htm": "html"}.get(suffix, suffix)
    if fmt is not None and fmt not in FORMATS:
        raise ValueError(f"--format {fmt!r}: use one of {', '.join(FORMATS)} (or -o's extension)")
    if fmt is not None and output is None:
        raise ValueError("--format is the format of -o: give -o FILE too")
    job = Comparison(
        parts=tuple(expand_parts(parts)),
        plan=PlanJob(
            "",
            Path(),
            "geometric",
            scan_spec(sensor, tolerance),
            units=units,
            roi=roi,
            table=table,
            robot=robot,
            tcp=tcp,
            part_pose=part_pose,
        ),  # fmt: skip
        plans=Path(),
        planners=tuple(p.strip() for p in planner.split(",") if p.strip()),
        views=tuple(v.strip() for v in views.split(",")) if views else (None,),
        points=points,
        seed=seed,
        trials=None if perturb is None else Trials(Perturbation.parse(perturb), trials),
        defects=DefectStudy(trials=defect_trials, seed=seed) if defects else None,
        require=() if require is None else parse_requirements(require),
    )
    job.check()
    say = (lambda _: None) if quiet else (lambda text: typer.echo(text, err=True))
    with tempfile.TemporaryDirectory() as scratch:
        rows = compare(replace(job, plans=plans or Path(scratch)), say)
    # Plans in the scratch folder are gone: no row names them.
    rows = hardest_first(rows if plans else [replace(r, plan_file="") for r in rows])
    typer.echo(to_text(rows), nl=False)
    if output is not None and fmt is not None:
        options = {"parts": parts, "planner": planner, "views": views, "robot": robot,
                   "points": points, "seed": seed, "perturb": perturb, "defects": defects,
                   "require": require}  # fmt: skip
        atomic_write_text(output, render(rows, fmt, options))
        say(f"-> {output}")
    errors, failed = failed_rows(rows)
    if errors:
        typer.echo(f"error: {errors} of {len(rows)} rows failed", err=True)
        raise typer.Exit(1)
    if failed:
        typer.echo(f"{failed} of {len(rows)} rows fail --require", err=True)
        raise typer.Exit(EXIT_FAILED_REQUIREMENT)
