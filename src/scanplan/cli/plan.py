"""`scanplan plan`: a trajectory over a part (or over each part of a catalogue), written with
what it was planned under, for the other commands to read.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer

from scanplan.cli.common import EXIT_FAILED_REQUIREMENT, progress_bar, user_errors
from scanplan.cli.options import (
    FixtureOpt,
    PartPoseOpt,
    PlanTcpOpt,
    PositionerOpt,
    QuietOpt,
    RequireOpt,
    RoiOpt,
    SensorOpt,
    TableOpt,
    ToleranceOpt,
    TrackOpt,
    UnitsOpt,
    bounded,
    scan_spec,
)
from scanplan.cli.training import check_cluster
from scanplan.core.quantities import COVERAGE_TARGET, OVERLAP, VIEW_CHOICE_CANDIDATES
from scanplan.core.sensor_spec import DEFAULT_SENSOR

# ---- plan ---------------------------------------------------------------------------------
PlannerOpt = Annotated[
    str,
    typer.Option(
        metavar="NAME",
        help="geometric (follows the CAD surface), feedback (a controller on what the sensor "
        "measures), rl (the paper's learned agent) or fixed (the paper's constant-height "
        "baseline)",
    ),
]
PlanOutOpt = Annotated[
    Path,
    typer.Option(
        "-o",
        "--output",
        metavar="PATH",
        help="output file: the plan (.csv or .json); output folder for a folder or list of "
        "parts (one NAME.json each)",
    ),
]
PolicyOpt = Annotated[
    Path | None,
    typer.Option(
        help="trained policy (directory or policy.json) for --planner rl, or a shipped one: "
        "default, v1 (rolls), paper (pure PPO from scratch)"
    ),
]
DirectionOpt = Annotated[
    str,
    typer.Option(
        metavar="DIR",
        help="scan direction: along x, along y, long (the long side of the part's outline seen "
        "from above) or auto (the long side, unless scanning across keeps the surface under "
        "the laser line clearly flatter)",
    ),
]
OverlapOpt = Annotated[
    float,
    typer.Option(
        help="overlap of adjacent passes of the nominal raster, a fraction of the line width, "
        "[0, 1)",
        callback=bounded(0, 1, hi_open=True),
    ),
]
RasterOpt = Annotated[
    str,
    typer.Option(
        metavar="MODE",
        help="how passes are spaced: nominal (the paper's: line width x (1 - overlap)), "
        "adaptive (by the part of the laser line that stays in spec there, closer on curved "
        "surface) or auto (adaptive if the planner rolls)",
    ),
]
RollOpt = Annotated[
    bool,
    typer.Option(
        "--roll/--no-roll",
        help="geometric and feedback: tilt the laser line with a surface that slopes across "
        "it (--no-roll: the paper's model, which only pitches); rl does what its policy does",
    ),
]
PlanViewsOpt = Annotated[
    str | None,
    typer.Option(
        metavar="MODE",
        help="how to plan views: top (the paper's single raster looking down) or auto (views "
        "from other directions added while they raise in-spec coverage, up to "
        "--coverage-target); default: auto if the planner rolls, else top",
        show_default=False,
    ),
]
PlanRobotOpt = Annotated[
    str | None,
    typer.Option(
        "--robot",
        metavar="ARM",
        help="plan for this arm: ur3e, ur5e, ur10e, kr6-r900, irb2400, lrmate200id or a TOML "
        "file of its kinematics; poses it cannot fly are given up and plan says what that cost",
        show_default=False,
    ),
]
CoverageTargetOpt = Annotated[
    float,
    typer.Option(
        help="--views auto: stop adding views once in-spec coverage of the surface to inspect "
        "reaches this fraction"
    ),
]


ViewCandidatesOpt = Annotated[
    int,
    typer.Option(
        "--view-candidates",
        help="--views auto: candidate views the choice may plan; past them the views chosen "
        "so far are kept (plan says so). Counted in work, so a busy and a quiet machine plan "
        "the same views",
        callback=bounded(1, 100_000),
    ),
]
ViewSecondsOpt = Annotated[
    float | None,
    typer.Option(
        "--view-seconds",
        help="--views auto: also stop choosing views after this many seconds (off by default: "
        "the plan then depends on the machine's load; the plan says when it stopped)",
        callback=bounded(0, None, lo_open=True),
        show_default=False,
    ),
]
PlanSchedulerOpt = Annotated[
    str | None,
    typer.Option(
        "--scheduler",
        help="plan on the Dask scheduler tcp://HOST:8786 (default: every core here): a "
        "catalogue's parts (a folder or a .txt list), or one part's candidate views "
        "(--views auto)",
        show_default=False,
    ),
]


@user_errors
def plan_cmd(
    part: Annotated[
        str,
        typer.Argument(
            help="built-in part name, mesh file (STL/OBJ/PLY/OFF/GLB) or STEP file, optionally "
            "with its units as PATH:UNITS (part.stl:in); or a folder of them, or a .txt list of "
            "them, one 'PATH [UNITS]' a line (each planned with the same options, -o then the "
            "folder for the plans)"
        ),
    ],
    output: PlanOutOpt,
    planner: PlannerOpt = "geometric",
    sensor: SensorOpt = DEFAULT_SENSOR,
    policy: PolicyOpt = None,
    direction: DirectionOpt = "auto",
    overlap: OverlapOpt = OVERLAP,
    raster: RasterOpt = "auto",
    roll: RollOpt = True,
    units: UnitsOpt = "mm",
    tolerance: ToleranceOpt = None,
    quiet: QuietOpt = False,
    roi: RoiOpt = None,
    views: PlanViewsOpt = None,
    coverage_target: CoverageTargetOpt = COVERAGE_TARGET,
    table: TableOpt = None,
    fixture: FixtureOpt = None,
    robot: PlanRobotOpt = None,
    tcp: PlanTcpOpt = None,
    part_pose: PartPoseOpt = None,
    positioner: PositionerOpt = None,
    track: TrackOpt = None,
    scheduler: PlanSchedulerOpt = None,
    view_candidates: ViewCandidatesOpt = VIEW_CHOICE_CANDIDATES,
    view_seconds: ViewSecondsOpt = None,
    require: RequireOpt = None,
):
    """Plan a scan trajectory over a part; write it as CSV or JSON, with what it was planned
    under (part, sensor, tolerances, views, region of interest, table and fixtures, arm) for
    the other commands to read. With --robot, a plan that arm can fly (placed by the tool
    unless --part-pose is given), and what that cost. A folder of parts, or a .txt file
    listing them (one 'PATH [UNITS]' a line, relative to the list; # comments), is a catalogue: each
    part planned on its own core (or Dask worker) into -o/NAME.json, one line per part."""
    # Deferred: the planners load trimesh, Embree and FCL (seconds), which --help need not.
    from scanplan.jobs.catalogue import catalogue_jobs, is_catalogue, plan_catalogue
    from scanplan.jobs.plan import PlanJob, run_plan_job
    from scanplan.judging.verdict import parse_requirements
    from scanplan.world.part_list import parse_part

    job = PlanJob(
        part, output, planner, scan_spec(sensor, tolerance), policy, direction, overlap,
        raster, roll, units, roi, views, coverage_target, table, tuple(fixture or ()), robot,
        tcp, part_pose, view_candidates, view_seconds,
        require=() if require is None else parse_requirements(require),
        positioner=positioner, track=track,
    )  # fmt: skip
    job.budget()  # a bad budget or criterion is named before any work
    job.check_require()
    if is_catalogue(part):
        check_cluster(scheduler, None)
        jobs = catalogue_jobs(job)
        with progress_bar(f"planning {len(jobs)} parts", quiet) as progress:
            results = plan_catalogue(jobs, scheduler, progress)
        failed = verdicts_failed = 0
        for name, done, error in results:
            if error is not None:
                failed += 1
                typer.echo(f"{name}: error: {error}", err=True)
            for text, to_stderr in done.lines:
                typer.echo(f"{name}: {text}", err=to_stderr)
            verdicts_failed += done.failed
        if failed:
            typer.echo(f"error: {failed} of {len(jobs)} parts not planned", err=True)
            raise typer.Exit(1)
        if verdicts_failed:
            typer.echo(f"{verdicts_failed} of {len(jobs)} plans fail --require", err=True)
            raise typer.Exit(EXIT_FAILED_REQUIREMENT)
        return
    ref = parse_part(part)  # part.stl:in, as in a list
    job = replace(job, part=ref.source, units=ref.units_or(units))
    if scheduler is not None:
        check_cluster(scheduler, None)
        job = replace(job, scheduler=scheduler)
    if output.suffix.lower() not in (".csv", ".json"):
        raise ValueError(f"output {output} must be a .csv or .json file")
    with progress_bar(f"planning ({planner})", quiet) as progress:
        done = run_plan_job(job, progress)
    for text, to_stderr in done.lines:
        typer.echo(text, err=to_stderr)
    if done.failed:
        raise typer.Exit(EXIT_FAILED_REQUIREMENT)
