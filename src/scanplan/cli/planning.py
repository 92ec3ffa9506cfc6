"""`scanplan plan`, `scan` and `evaluate`: a trajectory over a part, the point cloud it
measures, and the quality of that scan.
"""

from __future__ import annotations

import importlib.util
import json
import math
import multiprocessing
import os
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from scanplan.cli.common import progress_bar, user_errors
from scanplan.cli.options import (
    IDENTITY_POSE,
    POINTS_CHECK,
    FixtureOpt,
    Full3dOpt,
    OutOpt,
    PartArg,
    PartPoseOpt,
    QuietOpt,
    RoiOpt,
    SeedOpt,
    SensorOpt,
    TableOpt,
    TcpOpt,
    ToleranceOpt,
    TrajectoryArg,
    UnitsOpt,
    bounded,
    parse_tolerance,
    scan_spec,
)
from scanplan.cli.training import check_cluster
from scanplan.core.quantities import COVERAGE_TARGET, OVERLAP, VIEW_CHOICE_SECONDS, ScanSpec
from scanplan.core.sensor_spec import DEFAULT_SENSOR, SensorSpec

if TYPE_CHECKING:
    import numpy as np

    from scanplan.core.cycle import MotionLimits
    from scanplan.core.plan import PlanContext
    from scanplan.core.trajectory import Trajectory
    from scanplan.judging import Metrics
    from scanplan.planning.pipeline import Arm

# ---- scan ---------------------------------------------------------------------------------
ScanTrajectoryArg = Annotated[Path, typer.Argument(help="trajectory file (CSV or JSON)")]
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


@user_errors
def scan_cmd(
    part: PartArg,
    trajectory: ScanTrajectoryArg,
    output: OutOpt,
    sensor: SensorOpt = DEFAULT_SENSOR,
    units: UnitsOpt = "mm",
    seed: SeedOpt = 0,
    no_noise: NoNoiseOpt = False,
    quiet: QuietOpt = False,
    roi: RoiOpt = None,
    points: ScanPointsOpt = None,
    max_points: MaxPointsOpt = None,
):
    """Simulate the scan of a trajectory; write the point cloud (PLY) with error fields. The
    full cloud of a large part runs to GB: its size is printed first, and --points or
    --max-points write fewer."""
    # Deferred: the simulator loads trimesh, Embree and scipy.
    from scanplan.core.sensor_files import load_sensor
    from scanplan.core.trajectory import read_trajectory
    from scanplan.sensor.cloud import ply_size_bytes, simulate_cloud, write_ply
    from scanplan.world.part import load_part

    if output.suffix.lower() != ".ply":
        raise ValueError(f"output {output} must be a .ply file")
    spec = load_sensor(sensor)
    if no_noise:
        spec = spec.without_noise()
    if points is not None:
        spec = spec.with_points(points)
    the_part = load_part(part, units).with_roi(roi)
    traj = read_trajectory(trajectory)
    if not traj.scanning.any():
        raise ValueError(f"trajectory {trajectory} has no scanning pose")
    profiles = int(traj.scanning.sum())
    most = profiles * spec.points_per_profile
    kept = most if max_points is None else min(most, max_points)
    # Before scanning (stdout: stderr carries only an error's one line): a cloud of GB is
    # better cut now than found on the disk.
    typer.echo(
        f"scan: {profiles} profiles x {spec.points_per_profile} columns: up to {most:,} points"
        f" (~{_megabytes(ply_size_bytes(most))} as PLY)"
        + (f", at most {kept:,} kept (~{_megabytes(ply_size_bytes(kept))})" if kept < most else "")
        + ("" if kept < most or most <= 1_000_000 else "; --max-points N writes fewer")
    )
    with progress_bar("scanning", quiet) as progress:
        cloud = simulate_cloud(
            the_part, spec, traj, seed=seed, progress=progress, max_points=max_points
        )
    if len(cloud.points_part) == 0:
        raise ValueError(
            f"no valid point: part {part} is outside the sensor's reach along {trajectory}"
        )
    write_ply(cloud, output)
    typer.echo(
        f"{len(cloud.points_part)} points from {profiles} profiles -> {output} "
        f"({_megabytes(output.stat().st_size)})"
    )


# ---- plan ---------------------------------------------------------------------------------
PlannerOpt = Annotated[str, typer.Option(help="fixed, feedback, geometric or rl")]
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
        help="scan direction: x, y, long (the footprint's long side) or auto "
        "(the long side unless scanning across leaves clearly less cross-line error)"
    ),
]
OverlapOpt = Annotated[
    float,
    typer.Option(
        help="overlap of adjacent passes of the nominal raster, [0, 1)",
        callback=bounded(0, 1, hi_open=True),
    ),
]
RasterOpt = Annotated[
    str,
    typer.Option(
        help="nominal (the paper's: line width x (1 - overlap)), adaptive (passes spaced "
        "by the band of the line that stays in spec) or auto (adaptive if the planner rolls)"
    ),
]
RollOpt = Annotated[
    bool,
    typer.Option(
        "--roll/--no-roll",
        help="geometric/feedback: roll the line with the surface (--no-roll: the paper's "
        "pitch-only model); rl follows its policy",
    ),
]
PlanViewsOpt = Annotated[
    str | None,
    typer.Option(
        help="top (the paper's single top-down raster) or auto (views chosen greedily, "
        "each a raster of the part seen along its own axis, toward --coverage-target); "
        "default: auto if the planner rolls, else top",
        show_default=False,
    ),
]
PlanRobotOpt = Annotated[
    str | None,
    typer.Option(
        "--robot",
        help="plan for this arm (ur3e, ur5e, ur10e, kr6-r900, irb2400, lrmate200id or a TOML "
        "file): every pose reachable, no configuration flip within a pass",
        show_default=False,
    ),
]
CoverageTargetOpt = Annotated[
    float,
    typer.Option(
        help="--views auto: in-spec coverage (of the surface to inspect) to stop adding views at"
    ),
]


ViewSecondsOpt = Annotated[
    float,
    typer.Option(
        help="--views auto: seconds the choice of views may take; past them the views "
        "chosen so far are kept (plan says so)"
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


@dataclass(frozen=True)
class PlanJob:
    """One part's `scanplan plan`, picklable: what a worker process or a Dask task plans."""

    part: str
    output: Path
    planner: str
    sensor: str
    policy: Path | None
    direction: str
    overlap: float
    raster: str
    roll: bool
    units: str
    tolerance: str | None
    roi: str | None
    views: str | None
    coverage_target: float
    table: str | None
    fixture: tuple[str, ...]
    robot: str | None
    tcp: str | None
    part_pose: str | None
    view_seconds: float = VIEW_CHOICE_SECONDS
    scheduler: str | None = None  # one part's candidate views on this Dask scheduler


@user_errors
def plan_cmd(
    part: Annotated[
        str,
        typer.Argument(
            help="built-in part name, mesh file (STL/OBJ/PLY/OFF/GLB), STEP file, or a folder "
            "of them or a .txt list of them, one per line (each planned with the same options, "
            "-o then the folder for the plans)"
        ),
    ],
    output: OutOpt,
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
    tcp: TcpOpt = None,
    part_pose: PartPoseOpt = None,
    scheduler: PlanSchedulerOpt = None,
    view_seconds: ViewSecondsOpt = VIEW_CHOICE_SECONDS,
):
    """Plan a scan trajectory over a part; write it as CSV or JSON, with what it was planned
    under (sensor, tolerances, views, region of interest, table and fixtures) for `evaluate`
    to judge it by. With --robot, a plan that arm can fly (placed by the tool unless
    --part-pose is given), and what that cost. A folder of parts, or a .txt file listing
    them (one path a line, relative to the list; # comments), is a catalogue: each part
    planned on its own core (or Dask worker) into -o/NAME.json, one line per part."""
    job = PlanJob(
        part, output, planner, sensor, policy, direction, overlap, raster, roll, units,
        tolerance, roi, views, coverage_target, table, tuple(fixture or ()), robot, tcp,
        part_pose, view_seconds,
    )  # fmt: skip
    if not (math.isfinite(view_seconds) and view_seconds > 0):
        raise ValueError(f"--view-seconds must be a number of seconds > 0, got {view_seconds}")
    if Path(part).is_dir() or Path(part).suffix.lower() == CATALOGUE_LIST_SUFFIX:
        plan_catalogue(job, scheduler, quiet)
        return
    if scheduler is not None:
        check_cluster(scheduler, None)
        if importlib.util.find_spec("distributed") is None:
            raise ValueError(CLUSTER_HINT)
        job = replace(job, scheduler=scheduler)
    if output.suffix.lower() not in (".csv", ".json"):
        raise ValueError(f"output {output} must be a .csv or .json file")
    with progress_bar(f"planning ({planner})", quiet) as progress:
        lines = run_plan_job(job, progress)
    for text, to_stderr in lines:
        typer.echo(text, err=to_stderr)


def run_plan_job(
    job: PlanJob, progress: Callable[[int, int], None] | None = None
) -> list[tuple[str, bool]]:
    """Plan `job`, write its plan, and return what to print: (line, to stderr)."""
    # Deferred: planners and views load trimesh, Embree, FCL and (rl) torch.
    from scanplan.core.cycle import cycle_time
    from scanplan.core.plan import LOWEST
    from scanplan.core.trajectory import write_csv, write_json
    from scanplan.planning.pipeline import plan_views
    from scanplan.rl.planners import make_planner
    from scanplan.world.part import load_part

    output = job.output
    spec = scan_spec(job.sensor, job.tolerance)
    the_part = load_part(job.part, job.units)
    the_planner = make_planner(job.planner, job.policy, job.roll)
    arm = robot_arm(job.robot, job.tcp, job.part_pose)
    plans, traj = plan_views(
        the_part,
        spec,
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
        view_seconds=job.view_seconds,
        scheduler=job.scheduler,
    )
    (write_json if output.suffix.lower() == ".json" else write_csv)(traj, output)
    n_view = f"{len(plans)} view{'s' * (len(plans) > 1)}, "
    targets, blended = program_targets(traj, spec)
    cycle = cycle_time(traj, spec, arm_limits(job.robot, traj), targets=targets, blended=blended)
    return [
        (
            f"{the_planner.name}: {n_view}{sum(p.passes for p in plans)} passes, "
            f"{int(traj.scanning.sum())} profiles, {traj.path_length_mm():.0f} mm, "
            f"planned in {traj.plan_time_s:.2f} s -> {output}",
            False,
        ),
        (cycle.line(), False),
        *plan_notes(traj, spec),
    ]


def catalogue_parts(folder: Path) -> list[Path]:
    """The part files (meshes and STEP) directly in `folder`, sorted; each must have its own
    name, as its plan is named after it."""
    from scanplan.world.part import MESH_SUFFIXES, STEP_SUFFIXES

    parts = sorted(
        p
        for p in folder.iterdir()
        if p.is_file() and p.suffix.lower() in MESH_SUFFIXES + STEP_SUFFIXES
    )
    if not parts:
        formats = ", ".join(MESH_SUFFIXES + STEP_SUFFIXES)
        raise ValueError(f"folder {folder} holds no part file ({formats})")
    stems = [p.stem for p in parts]
    if twice := sorted({s for s in stems if stems.count(s) > 1}):
        raise ValueError(f"folder {folder}: parts {', '.join(twice)} would share a plan name")
    return parts


# A catalogue listed in a text file rather than gathered in a folder: a .txt is no part file.
CATALOGUE_LIST_SUFFIX = ".txt"


def catalogue_list(listing: Path) -> list[tuple[str, str]]:
    """(the entry as written, the part to load) for each part a list file names: one a line,
    a path relative to the list's folder (or absolute, or a built-in part's name); blank
    lines and what follows a '#' are skipped. A missing or unreadable part is that part's
    failure, not the list's; the list itself must exist and name parts of distinct plan
    names."""
    try:
        text = listing.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ValueError(f"part list {listing} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"part list {listing}: cannot read it ({exc})") from None
    entries = [e for line in text.splitlines() if (e := line.split("#", 1)[0].strip())]
    if not entries:
        raise ValueError(f"part list {listing} names no part (one path a line, # comments)")
    base = listing.parent
    # A name with no suffix that is no file next to the list is left to `load_part`: a
    # built-in part, or its one-line error.
    parts = [(e, str(base / e) if (base / e).exists() or Path(e).suffix else e) for e in entries]
    stems = [Path(e).stem for e in entries]
    if twice := sorted({s for s in stems if stems.count(s) > 1}):
        raise ValueError(f"part list {listing}: parts {', '.join(twice)} would share a plan name")
    return parts


def plan_one_of_catalogue(job: PlanJob) -> tuple[list[tuple[str, bool]], str | None]:
    """In a worker: the lines of one part's plan, or the one-line reason it has none (a bad
    part is that part's failure, not the catalogue's)."""
    try:
        return run_plan_job(job), None
    except (ValueError, OSError) as exc:
        return [], str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def plan_catalogue(job: PlanJob, scheduler: str | None, quiet: bool) -> None:
    """Plan every part in the folder, or named by the list file, `job.part` with `job`'s
    options, into `job.output` (a folder) as NAME.json: on the cores here, or on the Dask
    scheduler. Each part's lines are printed under its name (a list's: its entry); if any
    part fails, the run exits 1 after the rest."""
    output = job.output
    if output.suffix:
        raise ValueError(
            f"-o {output}: with a catalogue of parts, -o is the folder the plans go to"
        )
    source = Path(job.part)
    if source.is_dir():
        parts = [(p.name, str(p)) for p in catalogue_parts(source)]
    else:
        parts = catalogue_list(source)
    if output.exists() and not output.is_dir():
        raise ValueError(f"-o {output} is a file: give a folder for the plans")
    output.mkdir(parents=True, exist_ok=True)
    jobs = [replace(job, part=p, output=output / f"{Path(p).stem}.json") for _, p in parts]
    with progress_bar(f"planning {len(jobs)} parts", quiet) as progress:
        with trial_runner(scheduler, len(jobs)) as run:
            results = list(counted(run, progress)(plan_one_of_catalogue, jobs))
    failed = 0
    for (name, _), (lines, error) in zip(parts, results, strict=True):
        if error is not None:
            failed += 1
            typer.echo(f"{name}: error: {error}", err=True)
            continue
        for text, to_stderr in lines:
            typer.echo(f"{name}: {text}", err=to_stderr)
    if failed:
        typer.echo(f"error: {failed} of {len(jobs)} parts not planned", err=True)
        raise typer.Exit(1)


def program_targets(traj: Trajectory, spec: ScanSpec) -> tuple[np.ndarray, np.ndarray]:
    """The poses a robot program of `traj` flies between (export's thinned targets at its
    default tolerances) and which of them it blends through: where the cycle time is timed,
    so plan, evaluate and export agree."""
    # Deferred: export loads the writers of every dialect.
    from scanplan.robot.export import ExportOptions, plan_motion

    motion = plan_motion(traj, ExportOptions(scan=spec))
    return motion.source, motion.blend_mm > 0


def arm_limits(robot: str | None, traj: Trajectory) -> MotionLimits:
    """The motion limits a plan's cycle is timed with: the arm given, else the one the plan
    records, else (and for an arm recorded only by a name no preset has) the nominal arm."""
    # Deferred: the robot package loads the kinematics.
    from scanplan.core.cycle import NOMINAL
    from scanplan.robot import motion_limits

    name = robot or (traj.meta.get("robot") or {}).get("robot")
    if name is None:
        return NOMINAL
    try:
        return motion_limits(name)
    except ValueError:
        return NOMINAL


def robot_arm(robot: str | None, tcp: str | None, part_pose: str | None) -> Arm | None:
    """The arm `plan --robot` makes the plan for (None: no robot); a TCP not given is the
    flange, and the output says so."""
    # Deferred: the pipeline loads the planners; export the writers of every dialect.
    from scanplan.planning.pipeline import Arm
    from scanplan.robot.export import parse_pose_arg

    if robot is None:
        for option, value in (("--tcp", tcp), ("--part-pose", part_pose)):
            if value is not None:
                raise ValueError(f"{option} needs --robot: the arm it refers to")
        return None
    if tcp is None:
        typer.echo(f"--tcp not given: {IDENTITY_POSE} (the sensor origin is the flange)")
    pose = None if part_pose is None else parse_pose_arg(part_pose)
    return Arm(robot, parse_pose_arg(tcp or IDENTITY_POSE), pose)


def plan_notes(traj: Trajectory, spec: ScanSpec) -> list[tuple[str, bool]]:
    """What the planner left out or overrode, one line each, (line, to stderr); none when
    all went to plan."""
    lines: list[tuple[str, bool]] = []
    if unreachable := traj.meta.get("views_unreachable", 0):
        lines.append((f"views: {unreachable} left out, no collision-free move reaches them", False))
    if dropped := traj.meta.get("collisions_dropped", 0):
        lines.append(
            (
                f"collisions: {dropped} scanning poses dropped (sensor body within "
                f"{spec.clearance_mm:g} mm of the part, the table or a fixture)",
                False,
            )
        )
    if seconds := traj.meta.get("view_choice_out_of_time"):
        lines.append(
            (
                f"views: the choice stopped after {seconds:g} s with the views chosen by then "
                "(--view-seconds gives it longer)",
                False,
            )
        )
    if unreached := traj.meta.get("unreachable_dropped", 0):
        lines.append(
            (
                f"moves: {unreached} scanning poses given up (no move clear of the part and "
                "the cell reaches the piece of pass they are on)",
                False,
            )
        )
    if arm := traj.meta.get("robot"):
        given_up = ", ".join(f"view {k}: {v}" for k, v in arm["scanning_poses_given_up"].items())
        lines.append(
            (
                f"{arm['robot']} at --part-pose {arm['part_pose']}: "
                f"{sum(arm['scanning_poses_given_up'].values())} scanning poses given up"
                f"{f' ({given_up})' if given_up else ''}, {arm['moves_given_up']} move poses, "
                f"{arm['passes_split']} passes split at a configuration flip, "
                f"{arm.get('passes_turned', 0)} turned half a turn about the beam (links kept "
                f"clear of the part, table and fixtures); in-spec coverage "
                f"{arm['in_spec_without_robot']:.3f} without the arm, {arm['in_spec']:.3f} with it",
                False,
            )
        )
        if not arm.get("flyable", arm["reachable"]):
            lines.append(
                (
                    f"warning: {arm['robot']} still cannot fly every pass; export will say where",
                    True,
                )
            )
    if overrides := {k: v for k, v in traj.meta.items() if k.endswith("_overrides") and v}:
        # The rl planner's guards replaced some of the policy's steps: say how many.
        lines.append(("guard steps: " + ", ".join(f"{k} {v}" for k, v in overrides.items()), False))
    return lines


# ---- evaluate -----------------------------------------------------------------------------
JsonOpt = Annotated[bool, typer.Option("--json", help="print one JSON object")]
ReportDirOpt = Annotated[
    Path | None,
    typer.Option("-o", "--output", help="report directory (maps, metrics, report.html)"),
]
EvaluatePointsOpt = Annotated[
    int | None,
    typer.Option(
        "--points",
        help=f"sub-sample the fan to N points (faster), 2 to {SensorSpec.MAX_POINTS}",
        callback=POINTS_CHECK,
    ),
]
EvaluateViewsOpt = Annotated[
    str | None,
    typer.Option(
        help="the surface to inspect: top (upward-visible) or auto (visible from the "
        "upper hemisphere); default: as the plan records it",
        show_default=False,
    ),
]
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
        "'place:2mm,1deg;warp:1mm@200mm;scale:0.1%;path:0.1mm,0.05deg' (each a σ; ±2mm: "
        "uniform bounds): placement error, as-built deviation (RMS along the normal @ "
        "wavelength), scale, robot path error",
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
CLUSTER_HINT = "--scheduler needs the cluster extra: pip install 'scanplan[cluster]'"
ClosedLoopOpt = Annotated[
    bool,
    typer.Option(
        "--closed-loop",
        help="with --perturb, a feedback or rl plan's controller runs again on each perturbed "
        "part, acting on its profiles as on a cell (default: the plan is replayed)",
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
    part: PartArg,
    trajectory: TrajectoryArg,
    as_json: JsonOpt = False,
    output: ReportDirOpt = None,
    sensor: EvaluateSensorOpt = None,
    units: UnitsOpt = "mm",
    points: EvaluatePointsOpt = None,
    seed: SeedOpt = 0,
    tolerance: ToleranceOpt = None,
    quiet: QuietOpt = False,
    roi: RoiOpt = None,
    views: EvaluateViewsOpt = None,
    table: TableOpt = None,
    fixture: FixtureOpt = None,
    full_3d: Full3dOpt = False,
    perturb: PerturbOpt = None,
    trials: TrialsOpt = 16,
    scheduler: EvaluateSchedulerOpt = None,
    closed_loop: ClosedLoopOpt = False,
    policy: EvaluatePolicyOpt = None,
):
    """Simulate the scan of a trajectory and report its quality, judged as the plan file
    records it (sensor, tolerance, region of interest, surface) unless an option says
    otherwise. With --perturb, also how that in-spec coverage holds on seeded perturbed
    parts (mean, p5, worst over the trials) and which surface is fragile: the plan replayed
    as planned, or with --closed-loop its controller (feedback, rl) acting on the profiles of
    each perturbed part."""
    # Deferred: metrics load trimesh, Embree and FCL; the report, matplotlib and plotly.
    from scanplan.core.trajectory import read_trajectory
    from scanplan.judging.detectability import evaluate_detectable
    from scanplan.sensor.perturb import Perturbation
    from scanplan.world.cell import planned_cell
    from scanplan.world.part import load_part

    model = Perturbation.parse(perturb) if perturb is not None else None
    if model is None and scheduler is not None:
        raise ValueError("--scheduler runs --perturb's trials: give --perturb too")
    if model is None and closed_loop:
        raise ValueError("--closed-loop runs --perturb's trials in closed loop: give --perturb")
    if policy is not None and not closed_loop:
        raise ValueError("--policy is the rl plan's policy for --closed-loop: give --closed-loop")
    check_cluster(scheduler, None)
    traj = read_trajectory(trajectory)
    context, note = judged_context(traj, sensor, tolerance, roi, views, table, fixture)
    the_part = load_part(part, units)
    planned_cell(context, the_part.with_roi(context.roi))  # a bad ROI, table or fixture: fail first
    if closed_loop:  # a plan the closed loop cannot run: say so before the long part
        from scanplan.jobs.trials import closed_loop_planner, plan_views_of

        closed_loop_planner(context, policy, f"plan {trajectory}")
        plan_views_of(traj, f"plan {trajectory}")
    if note:
        typer.echo(note, err=True)
    targets, blended = program_targets(traj, context.spec)
    with progress_bar("evaluating", quiet) as progress:
        metrics = evaluate_detectable(
            the_part,
            context.spec,
            traj,
            seed,
            points,
            progress=progress,
            context=context,
            limits=arm_limits(None, traj),
            targets=targets,
            blended=blended,
        )
    robust = None
    if model is not None and closed_loop:
        from scanplan.jobs.trials import closed_loop_robustness, closed_loop_tasks

        loop_tasks = closed_loop_tasks(
            the_part, traj, context, model, trials, seed, points, policy, f"plan {trajectory}"
        )
        with progress_bar("trials", quiet) as progress, trial_runner(scheduler, trials) as run:
            robust = closed_loop_robustness(loop_tasks, counted(run, progress))
    elif model is not None:
        from scanplan.judging import robustness, trial_tasks

        tasks = trial_tasks(
            the_part, context.spec, traj, model, trials, seed, points, context=context
        )
        with progress_bar("trials", quiet) as progress, trial_runner(scheduler, trials) as run:
            robust = robustness(tasks, counted(run, progress))
    if output is not None:
        from scanplan.judging.report import Evaluated, write_report

        label = traj.planner or trajectory.stem
        write_report(
            output,
            the_part.with_roi(context.roi),
            [Evaluated(label, traj, metrics)],
            context.spec,
            title=f"{the_part.name}: {trajectory.name}",
            full_3d=full_3d,
        )
    data = metrics.to_json_dict()
    if robust is not None:
        data["robustness"] = {"nominal": metrics.in_spec_coverage, **robust.to_json_dict()}
        if output is not None:
            from scanplan.judging.report.maps import plot_fragility_map

            robust.write_csv(output / "fragility.csv")
            plot_fragility_map(
                robust, output / "fragility.png", f"{the_part.name}: {trajectory.name}"
            )
    if as_json:
        typer.echo(json.dumps(data, allow_nan=False))
        return
    typer.echo(metrics_line(metrics, data) + (f" -> {output}" if output is not None else ""))
    if metrics.cycle is not None:
        typer.echo(metrics.cycle.line())
    if robust is not None:
        typer.echo(robust.line(metrics.in_spec_coverage))


@contextmanager
def trial_runner(scheduler: str | None, trials: int) -> Iterator[Any]:
    """A map(function, tasks) for independent tasks (trials, a catalogue's parts): on the
    Dask scheduler at `scheduler`, else over worker processes, one per core (one after
    another if one suffices)."""
    if scheduler is not None:
        try:
            from dask.distributed import Client
        except ImportError:
            raise ValueError(CLUSTER_HINT) from None
        try:
            with Client(scheduler) as client:
                yield lambda f, tasks: client.gather(client.map(f, tasks, pure=False))
        except (OSError, TimeoutError) as exc:  # no scheduler there, or it went away
            raise ValueError(f"--scheduler {scheduler}: {exc}".splitlines()[0]) from None
        return
    workers = min(os.cpu_count() or 1, trials)
    if workers == 1:
        yield map
        return
    # Spawned, not forked: the parent already runs Embree's threads.
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(workers, mp_context=context) as pool:
        yield pool.map


def counted(run: Any, progress: Callable[[int, int], None] | None) -> Any:
    """`run` that reports each finished trial to `progress` (results stay in task order)."""
    if progress is None:
        return run

    def counting(f: Any, tasks: Any) -> Iterator[Any]:
        for i, result in enumerate(run(f, tasks)):
            progress(i + 1, len(tasks))
            yield result

    return counting


def judged_context(
    traj: Trajectory,
    sensor: str | None,
    tolerance: str | None,
    roi: str | None,
    views: str | None,
    table: str | None = None,
    fixtures: list[str] | None = None,
) -> tuple[PlanContext, str]:
    """The context to judge `traj` by: the one its file records, with what the options
    override (a file without a record: the defaults, and the surface its views imply); and
    one line saying where that differs from the plan ('' if nowhere)."""
    # Deferred: config reads TOML/YAML datasheets; context pulls in the quantities.
    from scanplan.core.plan import VIEW_MODES, recorded
    from scanplan.core.sensor_files import load_sensor

    if views is not None and views not in VIEW_MODES:
        raise ValueError(f"unknown --views {views!r}; use top or auto")
    planned = recorded(traj, ScanSpec())
    spec = planned.spec
    if sensor is not None:
        spec = replace(spec, sensor=load_sensor(sensor))
    if tol := parse_tolerance(tolerance):
        spec = replace(
            spec, tol_distance_mm=tol["tol_distance_mm"], tol_angle_rad=tol["tol_angle_rad"]
        )
    judged = planned.with_options(
        spec, roi, views, table, None if fixtures is None else tuple(fixtures)
    )
    if traj.meta.get("context") is None:  # nothing recorded to differ from
        return judged, ""
    changes = planned.differences(judged)
    return judged, ("note: judged with " + "; ".join(changes)) if changes else ""


def metrics_line(metrics: Metrics, data: dict[str, Any]) -> str:
    """The scan's quality on one line: in-spec coverage first, then the errors behind it."""
    tol = data["tolerance"]
    return (
        f"in-spec coverage {metrics.in_spec_coverage:.1%} (±{tol['mm']:g} mm, {tol['deg']:g}°) "
        f"of the {metrics.surface} surface ({_grouped(metrics.visible_area_mm2)} mm²)"
        f"{_of_ceiling(metrics)}{_detectable(metrics)} | "
        f"coverage {metrics.coverage_fraction:.1%} | {data['profiles']} profiles | "
        f"|distance error| mean {metrics.distance_error_mean_abs_mm:.3f} "
        f"p95 {metrics.distance_error_p95_abs_mm:.3f} mm | orientation mean "
        f"{metrics.orientation_error_mean_deg:.2f} p95 {metrics.orientation_error_p95_deg:.2f} deg"
        f" | spacing {metrics.spacing_mean_mm:.3f} mm (cv {metrics.spacing_cv:.3f}, "
        f"{metrics.backward_steps} backward) | reward {metrics.reward_mean:.4f}"
        f" | collisions {metrics.collisions_count} within {metrics.clearance_mm:g} mm, "
        f"{metrics.collisions_touching} touching (worst {metrics.worst_penetration_mm:.1f} mm)"
    )


def _detectable(metrics: Metrics) -> str:
    """' | dent found at 90 %: 0.089 mm deep (predicted)', or nothing where not predicted."""
    found = metrics.detectable
    if not found:
        return ""
    a90 = found.get("a90_mm")
    size = f"{a90:.3f} mm deep" if a90 is not None else "none (too little of the surface seen)"
    return f" | {found['type']} found at 90 %: {size} (predicted)"


def _of_ceiling(metrics: Metrics) -> str:
    """', 84.1% of its visibility ceiling 97.3%', or nothing where it was not measured."""
    share = metrics.in_spec_of_ceiling
    if share is None or metrics.visibility_ceiling is None:
        return ""
    return f", {share:.1%} of its visibility ceiling {metrics.visibility_ceiling:.1%}"


def _megabytes(size_bytes: int) -> str:
    return f"{size_bytes / 1e6:.1f} MB"


def _grouped(value: float) -> str:
    """181 206: thousands grouped by spaces, as the tables print them."""
    return f"{value:,.0f}".replace(",", " ")
