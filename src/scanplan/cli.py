"""The `scanplan` command line (SPEC §8): parses, calls the library, prints.

Every user mistake ends as one line on stderr and exit code 2, with no partial output file
(writers in the library are atomic).
"""

from __future__ import annotations

import functools
import math
import re
import shutil
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer
import typer.core

from scanplan.quantities import COVERAGE_TARGET, ScanSpec
from scanplan.sensor import SensorSpec


class _OneLineErrors(typer.core.TyperGroup):
    """The app's Click group: a usage error (unknown option or command, missing argument, a
    value that does not convert or is out of bounds) is one line on stderr and exit 2, not
    Typer's boxed panel; --help stays rich."""

    def main(
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        windows_expand_args: bool = True,
        **extra: Any,
    ) -> Any:
        from typer._click.exceptions import ClickException

        try:
            rv = super().main(args, prog_name, complete_var, False, windows_expand_args, **extra)
        except ClickException as exc:
            if type(exc).__name__ == "NoArgsIsHelpError":  # bare `scanplan`: the help
                exc.show()
                code = 2
            else:
                typer.echo(f"error: {usage_message(exc)}", err=True)
                code = exc.exit_code
            if not standalone_mode:
                return code
            sys.exit(code)
        except typer.Abort:
            typer.echo("interrupted", err=True)
            if not standalone_mode:
                return 130
            sys.exit(130)
        if not standalone_mode:
            return rv
        sys.exit(rv if isinstance(rv, int) else 0)


def usage_message(exc: Exception) -> str:
    """A Click usage error as one line naming the option or argument."""
    message = getattr(exc, "message", str(exc))
    param = getattr(exc, "param", None)
    hint = getattr(exc, "param_hint", None)
    if hint is None and param is not None:
        hint = param.get_error_hint()
    if isinstance(hint, list | tuple):
        hint = " / ".join(hint)
    errors = getattr(exc.__cause__, "errors", None)
    if callable(errors):  # a pydantic conversion error
        first = (errors() or [{}])[0]
        kind = str(first.get("type", ""))
        value = first.get("input")
        if kind.startswith("int_"):
            message = f"{value!r} is not a valid integer"
        elif kind.startswith("float_"):
            message = f"{value!r} is not a valid number"
        elif "input" in first:
            message = f"{value!r}: {first.get('msg', message)}"
    if type(exc).__name__ == "MissingParameter" or not hint:
        text = exc.format_message() if hasattr(exc, "format_message") else message
    else:
        text = f"{str(hint).replace(chr(39), '')}: {message}"
    ctx = getattr(exc, "ctx", None)
    where = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
    return " ".join(f"{text}{where}".split())


app = typer.Typer(
    cls=_OneLineErrors,
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Plan, simulate, evaluate and export laser-profilometer scan trajectories.",
)

F = TypeVar("F", bound=Callable[..., Any])


def user_errors(fn: F) -> F:
    """Turn the library's ValueError (and file errors) into one clear line and exit 2."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except (ValueError, OSError) as exc:
            message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            typer.echo(f"error: {message}", err=True)
            raise typer.Exit(2) from None
        except KeyboardInterrupt:
            typer.echo("interrupted", err=True)
            raise typer.Exit(130) from None

    return wrapper  # type: ignore[return-value]


def bounded(
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
) -> Callable[[Any], Any]:
    """A Typer callback refusing a number outside [lo, hi] (open ends on request), NaN and
    infinities; Click names the option in the error."""
    interval = (
        f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
        if lo is not None and hi is not None
        else f"{'>' if lo_open else '>='} {lo:g}"
        if lo is not None
        else f"{'<' if hi_open else '<='} {hi:g}"
        if hi is not None
        else "finite"
    )

    def check(value: Any) -> Any:
        if value is None:
            return value
        if not math.isfinite(value):
            raise typer.BadParameter(f"{value} is not a finite number")
        below = lo is not None and (value <= lo if lo_open else value < lo)
        above = hi is not None and (value >= hi if hi_open else value > hi)
        if below or above:
            verb = "is not in" if lo is not None and hi is not None else "must be"
            raise typer.BadParameter(f"{value:g} {verb} {interval}")
        return value

    return check


def pose_option(value: str) -> str:
    """--tcp / --part-pose: six finite numbers, checked before any work."""
    from scanplan.export import parse_pose_arg

    try:
        parse_pose_arg(value)
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None
    return value


@contextmanager
def progress_bar(label: str, quiet: bool) -> Iterator[Callable[[int, int], None] | None]:
    """A transient rich progress bar on stderr, fed by the library's progress(done, total);
    None (no output at all) with --quiet or when stderr is not a terminal."""
    if quiet or not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    columns = (TextColumn(label), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*columns, console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task(label, total=None)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield update


@contextmanager
def removed_on_error(directory: Path, keep: Callable[[Path], bool]) -> Iterator[None]:
    """Remove `directory` (and the parents made for it) if the block fails and it did not
    exist before, unless keep(directory) says it holds something worth resuming from."""
    created = None
    for candidate in (directory, *directory.parents):
        if candidate.exists():
            break
        created = candidate
    try:
        yield
    except BaseException:
        if created is not None and created.exists() and not keep(directory):
            shutil.rmtree(created, ignore_errors=True)
        raise


SEED_CHECK = bounded(0)
POSITIVE = bounded(0, lo_open=True)
POINTS_CHECK = bounded(2, SensorSpec.MAX_POINTS)

PartArg = Annotated[
    str, typer.Argument(help="built-in part name, mesh file (STL/OBJ/PLY/OFF/GLB) or STEP file")
]
UnitsOpt = Annotated[str, typer.Option("--units", help="units of a mesh file: mm, m or in")]
SensorOpt = Annotated[
    str, typer.Option("--sensor", help="sensor preset name or TOML/YAML datasheet file")
]
OutOpt = Annotated[Path, typer.Option("-o", "--output", help="output file")]
SeedOpt = Annotated[int, typer.Option(help="noise seed, >= 0", callback=SEED_CHECK)]
QuietOpt = Annotated[
    bool, typer.Option("--quiet", "-q", help="no progress bar (none either off a terminal)")
]
ToleranceOpt = Annotated[
    str | None,
    typer.Option(
        "--tolerance",
        help="in-spec tolerance MM,DEG: |z_s - W_d| in mm and orientation error in degrees "
        "(default Z_r/20 and 15)",
    ),
]


RoiOpt = Annotated[
    str | None,
    typer.Option(
        "--roi",
        help="region of interest: box:x0,y0,z0,x1,y1,z1 (mm), +z:30 (a normal cone; any of "
        "±x ±y ±z or n:X,Y,Z:DEG), body:I (the I-th connected body); ';' joins terms (AND)",
    ),
]


def parse_floats(text: str, option: str) -> tuple[float, ...]:
    """A comma-separated list of numbers, e.g. --log-std-init=-2,-2,-4."""
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"{option} {text!r}: expected numbers") from None


def parse_tolerance(text: str | None) -> dict[str, float]:
    """--tolerance MM,DEG as ScanSpec keyword arguments (none when not given)."""
    if text is None:
        return {}
    parts = text.split(",")
    try:
        mm, deg = (float(p) for p in parts) if len(parts) == 2 else (math.nan, math.nan)
    except ValueError:
        mm = deg = math.nan
    if not (math.isfinite(mm) and math.isfinite(deg) and mm > 0 and 0 < deg <= 90):
        raise ValueError(
            f"--tolerance {text!r}: expected MM,DEG with MM > 0 and 0 < DEG <= 90, e.g. 12.5,15"
        )
    return {"tol_distance_mm": mm, "tol_angle_rad": math.radians(deg)}


def scan_spec(sensor: str, tolerance: str | None = None) -> ScanSpec:
    """The ScanSpec of the --sensor and --tolerance options."""
    from scanplan.config import load_sensor

    tol = parse_tolerance(tolerance)  # before the sensor file: the cheaper check first
    return ScanSpec(load_sensor(sensor), **tol)


# ---- part -------------------------------------------------------------------------------
@app.command("part")
@user_errors
def part_cmd(name: Annotated[str, typer.Argument(help="built-in part name")], output: OutOpt):
    """Write a built-in procedural part as a mesh file (STL, PLY, OBJ, ...)."""
    from scanplan.part import load_part
    from scanplan.parts import PART_NAMES
    from scanplan.trajectory import atomic_write_bytes

    if name not in PART_NAMES:
        raise ValueError(f"unknown part {name!r}; built-in parts: {', '.join(PART_NAMES)}")
    part = load_part(name)
    file_type = output.suffix.lower().lstrip(".") or "stl"
    try:
        data = part.mesh.export(file_type=file_type)
    except (ValueError, KeyError, NotImplementedError):
        raise ValueError(
            f"cannot write mesh format {output.suffix!r}; use .stl, .ply or .obj"
        ) from None
    if not isinstance(data, bytes | str):
        raise ValueError(f"cannot write mesh format {output.suffix!r}; use .stl, .ply or .obj")
    atomic_write_bytes(output, data if isinstance(data, bytes) else data.encode())
    e = part.extents
    typer.echo(
        f"{name}: {len(part.mesh.faces)} triangles, {e[0]:.0f} x {e[1]:.0f} x {e[2]:.0f} mm "
        f"-> {output}"
    )


# ---- scan -------------------------------------------------------------------------------
@app.command("scan")
@user_errors
def scan_cmd(
    part: PartArg,
    trajectory: Annotated[Path, typer.Argument(help="trajectory CSV (SPEC §8 columns)")],
    output: OutOpt,
    sensor: SensorOpt = "at-c5-4090cs30-495",
    units: UnitsOpt = "mm",
    seed: SeedOpt = 0,
    no_noise: Annotated[bool, typer.Option("--no-noise", help="switch noise off")] = False,
    quiet: QuietOpt = False,
    roi: RoiOpt = None,
):
    """Simulate the scan of a trajectory; write the point cloud (PLY) with error fields."""
    from scanplan.cloud import simulate_cloud, write_ply
    from scanplan.config import load_sensor
    from scanplan.part import load_part
    from scanplan.trajectory import read_trajectory

    if output.suffix.lower() != ".ply":
        raise ValueError(f"output {output} must be a .ply file")
    spec = load_sensor(sensor)
    if no_noise:
        spec = spec.without_noise()
    the_part = load_part(part, units).with_roi(roi)
    traj = read_trajectory(trajectory)
    if not traj.scanning.any():
        raise ValueError(f"trajectory {trajectory} has no scanning pose")
    with progress_bar("scanning", quiet) as progress:
        cloud = simulate_cloud(the_part, spec, traj, seed=seed, progress=progress)
    if len(cloud.points_part) == 0:
        raise ValueError(
            f"no valid point: part {part} is outside the sensor's reach along {trajectory}"
        )
    write_ply(cloud, output)
    typer.echo(
        f"{len(cloud.points_part)} points from {int(traj.scanning.sum())} profiles -> {output}"
    )


# ---- plan / evaluate (planners and metrics) ----------------------------------------------
@app.command("plan")
@user_errors
def plan_cmd(
    part: PartArg,
    output: OutOpt,
    planner: Annotated[str, typer.Option(help="fixed, feedback, geometric or rl")] = "geometric",
    sensor: SensorOpt = "at-c5-4090cs30-495",
    policy: Annotated[
        Path | None, typer.Option(help="trained policy file for --planner rl")
    ] = None,
    direction: Annotated[
        str,
        typer.Option(
            help="scan direction: x, y, long (the footprint's long side) or auto "
            "(the long side unless scanning across leaves clearly less cross-line error)"
        ),
    ] = "auto",
    overlap: Annotated[
        float,
        typer.Option(
            help="overlap of adjacent passes of the nominal raster, [0, 1)",
            callback=bounded(0, 1, hi_open=True),
        ),
    ] = 0.2,
    raster: Annotated[
        str,
        typer.Option(
            help="nominal (the paper's: line width x (1 - overlap)), adaptive (passes spaced "
            "by the band of the line that stays in spec) or auto (adaptive if the planner rolls)"
        ),
    ] = "auto",
    roll: Annotated[
        bool,
        typer.Option(
            "--roll/--no-roll",
            help="geometric/feedback: roll the line with the surface (--no-roll: the paper's "
            "pitch-only model); rl follows its policy",
        ),
    ] = True,
    units: UnitsOpt = "mm",
    tolerance: ToleranceOpt = None,
    quiet: QuietOpt = False,
    roi: RoiOpt = None,
    views: Annotated[
        str | None,
        typer.Option(
            help="top (the paper's single top-down raster) or auto (views chosen greedily, "
            "each a raster of the part seen along its own axis, toward --coverage-target); "
            "default: auto if the planner rolls, else top",
            show_default=False,
        ),
    ] = None,
    coverage_target: Annotated[
        float, typer.Option(help="--views auto: in-spec coverage to stop adding views at")
    ] = COVERAGE_TARGET,
):
    """Plan a scan trajectory over a part; write it as CSV (SPEC §8 columns)."""
    from scanplan.part import load_part
    from scanplan.planners import make_planner, plan_scan
    from scanplan.trajectory import write_csv, write_json
    from scanplan.views import default_views, plan_views

    if output.suffix.lower() not in (".csv", ".json"):
        raise ValueError(f"output {output} must be a .csv or .json file")
    spec = scan_spec(sensor, tolerance)
    the_part = load_part(part, units).with_roi(roi)
    the_planner = make_planner(planner, policy, roll)
    views = default_views(the_planner) if views is None else views
    with progress_bar(f"planning ({the_planner.name})", quiet) as progress:
        if views == "top":
            swaths, traj = plan_scan(
                the_part, spec, the_planner, raster, direction, overlap, progress=progress
            )
            n_pass, n_view = len(swaths), ""
        else:
            plans, traj = plan_views(
                the_part, spec, the_planner, views, coverage_target, raster, direction, overlap
            )
            n_pass, n_view = sum(p.passes for p in plans), f"{len(plans)} views, "
    (write_json if output.suffix.lower() == ".json" else write_csv)(traj, output)
    typer.echo(
        f"{the_planner.name}: {n_view}{n_pass} passes, {int(traj.scanning.sum())} profiles, "
        f"{traj.path_length_mm():.0f} mm, planned in {traj.plan_time_s:.2f} s -> {output}"
    )
    if unreachable := traj.meta.get("views_unreachable", 0):
        typer.echo(f"views: {unreachable} left out, no collision-free move reaches them")
    if dropped := traj.meta.get("collisions_dropped", 0):
        typer.echo(
            f"collisions: {dropped} scanning poses dropped (sensor body within "
            f"{spec.clearance_mm:g} mm of the part)"
        )
    if overrides := {k: v for k, v in traj.meta.items() if k.endswith("_overrides") and v}:
        # The rl planner's guards replaced some of the policy's steps: say how many.
        typer.echo("guard steps: " + ", ".join(f"{k} {v}" for k, v in overrides.items()))


@app.command("evaluate")
@user_errors
def evaluate_cmd(
    part: PartArg,
    trajectory: Annotated[Path, typer.Argument(help="trajectory CSV or JSON")],
    as_json: Annotated[bool, typer.Option("--json", help="print one JSON object")] = False,
    output: Annotated[
        Path | None,
        typer.Option("-o", "--output", help="report directory (maps, metrics, report.html)"),
    ] = None,
    sensor: SensorOpt = "at-c5-4090cs30-495",
    units: UnitsOpt = "mm",
    points: Annotated[
        int | None,
        typer.Option(
            "--points",
            help=f"sub-sample the fan to N points (faster), 2 to {SensorSpec.MAX_POINTS}",
            callback=POINTS_CHECK,
        ),
    ] = None,
    seed: SeedOpt = 0,
    tolerance: ToleranceOpt = None,
    quiet: QuietOpt = False,
    roi: RoiOpt = None,
    views: Annotated[
        str | None,
        typer.Option(
            help="the surface to inspect: top (upward-visible) or auto (visible from the "
            "upper hemisphere); default: auto for a JSON trajectory of several views, else top"
        ),
    ] = None,
):
    """Simulate the scan of a trajectory and report its quality (SPEC §7)."""
    import json

    from scanplan.metrics import evaluate
    from scanplan.part import load_part
    from scanplan.trajectory import read_trajectory

    spec = scan_spec(sensor, tolerance)
    the_part = load_part(part, units).with_roi(roi)
    traj = read_trajectory(trajectory)
    if views not in (None, "top", "auto"):
        raise ValueError(f"unknown --views {views!r}; use top or auto")
    visible = {None: "auto", "top": "top", "auto": "hemisphere"}[views]
    with progress_bar("evaluating", quiet) as progress:
        metrics = evaluate(
            the_part,
            spec,
            traj,
            seed=seed,
            points_per_profile=points,
            visible=visible,
            progress=progress,
        )
    if output is not None:
        from scanplan.report import Evaluated, write_report

        label = traj.planner or trajectory.stem
        write_report(
            output,
            the_part,
            [Evaluated(label, traj, metrics)],
            spec,
            title=f"{the_part.name}: {trajectory.name}",
        )
    data = metrics.to_json_dict()
    if as_json:
        typer.echo(json.dumps(data, allow_nan=False))
        return
    tol = data["tolerance"]
    typer.echo(
        f"in-spec coverage {metrics.in_spec_coverage:.1%} (±{tol['mm']:g} mm, {tol['deg']:g}°) | "
        f"coverage {metrics.coverage_fraction:.1%} | {data['profiles']} profiles | "
        f"|distance error| mean {metrics.distance_error_mean_abs_mm:.3f} "
        f"p95 {metrics.distance_error_p95_abs_mm:.3f} mm | orientation mean "
        f"{metrics.orientation_error_mean_deg:.2f} p95 {metrics.orientation_error_p95_deg:.2f} deg"
        f" | spacing {metrics.spacing_mean_mm:.3f} mm (cv {metrics.spacing_cv:.3f}, "
        f"{metrics.backward_steps} backward) | reward {metrics.reward_mean:.4f}"
        f" | collisions {metrics.collisions_count} within {metrics.clearance_mm:g} mm, "
        f"{metrics.collisions_touching} touching (worst {metrics.worst_penetration_mm:.1f} mm)"
        + (f" -> {output}" if output is not None else "")
    )


# ---- train (RL) --------------------------------------------------------------------------
@app.command("train")
@user_errors
def train_cmd(
    output: Annotated[Path, typer.Option("-o", "--output", help="policy directory")],
    part: Annotated[
        list[str] | None, typer.Option("--part", help="training part(s): built-in name or mesh")
    ] = None,
    timesteps: Annotated[
        int, typer.Option(help="total PPO timesteps, >= 1", callback=bounded(1))
    ] = 1_000_000,
    seed: Annotated[
        int, typer.Option(help="seed of PPO and the environments, >= 0", callback=SEED_CHECK)
    ] = 0,
    n_envs: Annotated[
        int,
        typer.Option(
            "--n-envs", help="parallel environments, 1 to 1024", callback=bounded(1, 1024)
        ),
    ] = 16,
    vec: Annotated[
        str, typer.Option(help="batched (envs stepped together, one process) | subproc")
    ] = "batched",
    resume: Annotated[
        Path | None, typer.Option(help="continue from the latest checkpoint in DIR")
    ] = None,
    state: Annotated[
        str, typer.Option(help="paper (P, θ, D, α, Δs) | no-position | lookahead")
    ] = "paper",
    env_version: Annotated[
        str, typer.Option("--env", help="v0 (the paper's) | v1 (with roll: Δφ, φ and β)")
    ] = "v0",
    procedural: Annotated[
        int,
        typer.Option(help="also train on N randomized procedural parts, >= 0", callback=SEED_CHECK),
    ] = 0,
    fan_points: Annotated[
        int | None,
        typer.Option(
            help=f"sub-sampled fan for training, 2 to {SensorSpec.MAX_POINTS} "
            "(default: the env's training fan, 128)",
            callback=POINTS_CHECK,
        ),
    ] = None,
    log_std_init: Annotated[
        str, typer.Option(help="initial log std: one value, or Δy,Δz,Δθ (SB3 default 0)")
    ] = "0",
    init_advance: Annotated[
        float | None,
        typer.Option(
            help="initial mean Δy action (0.5 = Δs_opt); default none", callback=bounded()
        ),
    ] = None,
    bc_samples: Annotated[
        int,
        typer.Option(
            help="warm start: behaviour-clone a P-controller on N states first",
            callback=SEED_CHECK,
        ),
    ] = 0,
    no_progress: Annotated[
        bool, typer.Option("--no-progress", "--quiet", "-q", help="no progress bar")
    ] = False,
):
    """Train the pass agent with PPO (the paper's hyperparameters) and write a policy."""
    import shlex

    from scanplan.learn.config import recipe_config
    from scanplan.learn.train import train

    if resume is not None and not resume.is_dir():
        raise ValueError(f"--resume {resume} is not a directory")
    config = recipe_config(
        str(output),
        parts=tuple(part or ["training-piece"]),
        timesteps=timesteps,
        seed=seed,
        n_envs=n_envs,
        vec_env=vec,
        state=state,
        env_version=env_version,
        procedural=procedural,
        fan_points=fan_points,
        log_std_init=parse_floats(log_std_init, "--log-std-init"),
        init_advance=init_advance,
        bc_samples=bc_samples,
        resume=str(resume) if resume else None,
        progress_bar=not no_progress,
        command=shlex.join(["scanplan", *sys.argv[1:]]),
    )
    from scanplan.learn.checkpoint import CHECKPOINT_DIR

    def has_checkpoint(out: Path) -> bool:
        return any((out / CHECKPOINT_DIR).glob("*.json"))

    with removed_on_error(output, keep=has_checkpoint):
        result = train(config)
    f = result.final
    typer.echo(
        f"{result.timesteps} timesteps in {result.wall_time_s:.0f} s | reward/step "
        f"{f['reward_per_step']:.4f} (R_D {f['r_d']:.4f}, R_α {f['r_alpha']:.4f}, "
        f"R_Δs {f['r_delta_s']:.4f}) -> {result.policy_json}"
    )


def parse_grid(items: list[str]) -> dict[str, list[Any]]:
    """--grid KEY=V1,V2 (values as JSON where they parse, e.g. [-2,-2,-4], else strings)."""
    import json
    import re

    grid: dict[str, list[Any]] = {}
    for item in items:
        key, sep, values = item.partition("=")
        if not sep or not key or not values:
            raise ValueError(f"--grid {item!r}: expected KEY=V1,V2,...")
        parsed = []
        for text in re.split(r",(?![^\[]*\])", values):
            try:
                value = json.loads(text)
            except json.JSONDecodeError:
                value = text
            parsed.append(tuple(value) if isinstance(value, list) else value)
        grid[key.strip()] = parsed
    return grid


@app.command("sweep")
@user_errors
def sweep_cmd(
    output: Annotated[Path, typer.Option("-o", "--output", help="directory of runs and tables")],
    part: Annotated[
        list[str] | None,
        typer.Option("--part", help="unseen part(s) to evaluate on: name or PATH[:UNITS]"),
    ] = None,
    seeds: Annotated[str, typer.Option(help="training seeds, e.g. 0,1,2")] = "0,1,2",
    grid: Annotated[
        list[str] | None,
        typer.Option("--grid", help="KEY=V1,V2: a TrainConfig field (or env.NAME) and its values"),
    ] = None,
    label: Annotated[str, typer.Option(help="row label of the trained runs")] = "rl",
    baseline: Annotated[
        list[str] | None,
        typer.Option("--baseline", help="also evaluate an untrained planner: feedback, geometric"),
    ] = None,
    scheduler: Annotated[
        str | None, typer.Option(help="Dask scheduler tcp://HOST:8786 (default: a LocalCluster)")
    ] = None,
    workers: Annotated[
        int | None, typer.Option(help="LocalCluster workers (default: one per core)")
    ] = None,
    timesteps: Annotated[int, typer.Option(help="PPO timesteps per run (0: BC only)")] = 61_440,
    state: Annotated[str, typer.Option(help="paper | no-position | lookahead")] = "paper",
    env_version: Annotated[str, typer.Option("--env", help="v0 | v1")] = "v0",
    procedural: Annotated[int, typer.Option(help="N randomized procedural parts")] = 0,
    fan_points: Annotated[
        int | None,
        typer.Option(
            help="sub-sampled fan for training (default: the env's, 128)", callback=POINTS_CHECK
        ),
    ] = None,
    log_std_init: Annotated[str, typer.Option(help="initial log std, as for train")] = "0",
    init_advance: Annotated[float | None, typer.Option(help="initial mean Δy action")] = None,
    bc_samples: Annotated[int, typer.Option(help="behaviour-cloning warm start states")] = 0,
    n_envs: Annotated[int, typer.Option("--n-envs", help="envs per run")] = 16,
):
    """Train seeds x a grid of configs as Dask tasks, evaluate each policy on unseen parts,
    and write sweep.csv (per run and part) and sweep.md (mean ± sd over seeds)."""
    import shlex

    from scanplan.learn.sweep import CLUSTER_HINT

    try:
        import dask.distributed  # noqa: F401
    except ImportError:
        raise ValueError(CLUSTER_HINT) from None
    from scanplan.learn.config import recipe_config
    from scanplan.learn.sweep import (
        EvalPart,
        SweepTask,
        connect,
        grid_tasks,
        run_sweep,
        write_tables,
    )

    seed_list = [int(v) for v in parse_floats(seeds, "--seeds")]
    command = shlex.join(["scanplan", *sys.argv[1:]])
    base = recipe_config(
        str(output),
        timesteps=timesteps,
        n_envs=n_envs,
        state=state,
        env_version=env_version,
        procedural=procedural,
        fan_points=fan_points,
        log_std_init=parse_floats(log_std_init, "--log-std-init"),
        init_advance=init_advance,
        bc_samples=bc_samples,
        progress_bar=False,
        command=command,
    )
    tasks = grid_tasks(label, base, output / "runs", seed_list, parse_grid(grid or []))
    roll = env_version == "v1"
    for name in baseline or []:
        if name not in ("fixed", "feedback", "geometric"):
            raise ValueError(f"--baseline {name!r}: use fixed, feedback or geometric")
    tasks += [SweepTask(name, planner=name, roll=roll) for name in baseline or []]
    parts = [EvalPart.parse(p) for p in part or ["door", "drone"]]
    if scheduler is not None and not re.fullmatch(r"(tcp|tls|inproc)://[^\s/]+", scheduler):
        raise ValueError(f"--scheduler {scheduler!r}: expected tcp://HOST:PORT")
    if workers is not None and workers < 1:
        raise ValueError(f"--workers: {workers} must be >= 1")

    def has_runs(directory: Path) -> bool:  # finished runs are reused by a rerun: keep them
        return any((directory / "runs").glob("**/policy.json"))

    with removed_on_error(output, keep=has_runs):
        output.mkdir(parents=True, exist_ok=True)
        try:
            with connect(scheduler, workers) as client:
                rows = run_sweep(
                    tasks,
                    parts,
                    client,
                    on_done=lambda done: typer.echo(
                        f"done: {done[0]['label']} seed {done[0]['seed']}", err=True
                    ),
                )
        except (OSError, TimeoutError) as exc:  # no scheduler there, or it went away
            raise ValueError(f"--scheduler {scheduler}: {exc}".splitlines()[0]) from None
        csv_path, md_path = write_tables(rows, output)
    typer.echo(md_path.read_text(), nl=False)
    typer.echo(f"-> {csv_path}, {md_path}")


# ---- export (robot programs) --------------------------------------------------------------
POSE_HELP = "x,y,z in mm then A,B,C in degrees (KUKA intrinsic ZYX: Rz(A) Ry(B) Rx(C))"
TcpOpt = Annotated[str, typer.Option(help=f"flange->sensor TCP: {POSE_HELP}", callback=pose_option)]
ROBOT_HELP = (
    "arm to check reach on: ur3e, ur5e, ur10e, kr6-r900, irb2400, lrmate200id or a TOML "
    "file of OPW parameters; 'none' to skip"
)


@app.command("export")
@user_errors
def export_cmd(
    trajectory: Annotated[Path, typer.Argument(help="trajectory CSV or JSON")],
    output: Annotated[
        Path, typer.Option("-o", "--output", help="output file (a directory for rosbag2)")
    ],
    fmt: Annotated[
        str, typer.Option("--format", help="urscript, rapid, krl, ros, rosbag2 or csv")
    ] = "urscript",
    tcp: TcpOpt = "0,0,0,0,0,0",
    part_pose: Annotated[
        str,
        typer.Option(
            "--part-pose", help=f"part in the robot base frame: {POSE_HELP}", callback=pose_option
        ),
    ] = "0,0,0,0,0,0",
    profile_rate: Annotated[
        float,
        typer.Option(
            help="sensor profile rate, Hz (> 0); scan speed = rate x spacing", callback=POSITIVE
        ),
    ] = ScanSpec.profile_rate_hz,
    spacing: Annotated[
        float, typer.Option(help="profile spacing on the part, mm (> 0)", callback=POSITIVE)
    ] = ScanSpec.delta_s_opt_mm,
    travel_speed: Annotated[
        float, typer.Option(help="speed between passes, mm/s (> 0)", callback=POSITIVE)
    ] = ScanSpec.travel_speed_mm_s,
    robot: Annotated[str, typer.Option(help=ROBOT_HELP)] = "ur5e",
    quiet: QuietOpt = False,
):
    """Write a robot program (URScript, ABB RAPID, KUKA KRL, ROS 2 YAML or bag, or CSV)."""
    from scanplan.export import (
        DIRECTORY_FORMATS,
        FORMATS,
        ExportOptions,
        export_program,
        export_rosbag,
        flange_poses,
        parse_pose_arg,
    )
    from scanplan.export.common import plan_motion
    from scanplan.robot import check_reach, get_robot
    from scanplan.trajectory import atomic_write_text, read_trajectory

    if fmt not in FORMATS and fmt not in DIRECTORY_FORMATS:
        choices = ", ".join([*FORMATS, *DIRECTORY_FORMATS])
        raise ValueError(f"unknown format {fmt!r}; use one of {choices}")
    if fmt in FORMATS and (str(output) in ("", ".") or output.is_dir()):
        raise ValueError(f"-o {str(output)!r} is a directory: give the program's file name")
    # KUKA wants the .src file named after its DEF.
    name = output.stem if output.stem.isidentifier() and len(output.stem) <= 24 else ""
    options = ExportOptions(
        part_pose=parse_pose_arg(part_pose),
        tcp=parse_pose_arg(tcp),
        scan=ScanSpec(
            delta_s_opt_mm=spacing, profile_rate_hz=profile_rate, travel_speed_mm_s=travel_speed
        ),
        program_name=name if name and fmt == "krl" else "scanplan_path",
    )
    traj = read_trajectory(trajectory)
    text = export_program(traj, fmt, options) if fmt in FORMATS else None
    if text is None:
        plan_motion(traj, options)  # refuse an unexportable trajectory before the reach check
    if robot.lower() != "none":
        with progress_bar("reach check", quiet):
            report = check_reach(
                flange_poses(traj, options),
                get_robot(robot),
                swath=traj.swath,
                scanning=traj.scanning,
            )
        if not report.ok:
            typer.echo(f"warning: {report.summary()}", err=True)
        else:
            typer.echo(report.summary())
    if text is not None:
        atomic_write_text(output, text)
    else:
        export_rosbag(traj, output, options)
    typer.echo(f"{fmt}: {len(traj)} poses, scan speed {options.scan_speed:.1f} mm/s -> {output}")


# ---- place (part pose for an arm) ---------------------------------------------------------
@app.command("place")
@user_errors
def place_cmd(
    trajectory: Annotated[Path, typer.Argument(help="trajectory CSV or JSON")],
    robot: Annotated[
        str,
        typer.Option(help="ur3e, ur5e, ur10e, kr6-r900, irb2400, lrmate200id or a TOML file"),
    ],
    tcp: TcpOpt = "0,0,0,0,0,0",
    height_range: Annotated[
        str | None,
        typer.Option("--height-range", help="LO,HI mm: the part origin's z in the base frame"),
    ] = None,
    yaw_step: Annotated[
        float,
        typer.Option(
            "--yaw-step",
            help="coarse yaw grid, deg, (0, 360]",
            callback=bounded(0, 360, lo_open=True),
        ),
    ] = 30.0,
    quiet: QuietOpt = False,
):
    """Search the part's pose on the table (x, y, z, yaw) from which the arm reaches every
    pose with no configuration flip in a pass; print it as --part-pose. Exit 2 if none does."""
    from scanplan.export import parse_pose_arg
    from scanplan.robot.place import place
    from scanplan.trajectory import read_trajectory

    heights: tuple[float, float] | None = None
    if height_range is not None:
        try:
            lo, hi = (float(v) for v in height_range.split(","))
        except ValueError:
            raise ValueError(f"--height-range {height_range!r}: expected LO,HI in mm") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
            raise ValueError(f"--height-range {height_range!r}: expected finite LO <= HI in mm")
        heights = (lo, hi)
    traj = read_trajectory(trajectory)
    with progress_bar("searching a placement", quiet):
        result = place(traj, robot, parse_pose_arg(tcp), heights, yaw_step)
    m = result.report.worst_margins()
    typer.echo(f"--part-pose {result.pose_arg()}")
    typer.echo(result.report.summary())
    typer.echo(
        f"worst margins: joint limit {m['limit_deg']:.1f} deg, wrist {m['wrist_deg']:.1f} deg, "
        f"elbow {m['elbow_deg']:.1f} deg, shoulder {m['shoulder_mm']:.0f} mm "
        f"({result.evaluated} placements in {result.seconds:.1f} s)"
    )
    if not result.reachable:
        typer.echo("error: no placement reaches every pose; the best found is above", err=True)
        raise typer.Exit(2)


# ---- demo ---------------------------------------------------------------------------------
@app.command("demo")
@user_errors
def demo_cmd(
    output: Annotated[Path, typer.Option("-o", "--output", help="output directory")] = Path(
        "out/demo"
    ),
    part: Annotated[str, typer.Option(help="built-in part or mesh file")] = "door",
    units: UnitsOpt = "mm",
    sensor: SensorOpt = "at-c5-4090cs30-495",
    points: Annotated[
        int,
        typer.Option(
            "--points",
            help=f"pixel columns per profile in the evaluation, 2 to {SensorSpec.MAX_POINTS}",
            callback=POINTS_CHECK,
        ),
    ] = 1024,
    seed: SeedOpt = 0,
    tolerance: ToleranceOpt = None,
    roi: RoiOpt = None,
):
    """The main job: three planners on a part (the door by default), the table, maps, an
    HTML report and a URScript program."""
    from rich.console import Console
    from rich.table import Table

    from scanplan.demo import run_demo
    from scanplan.report.table import table_rows

    console = Console(log_path=False)
    spec = scan_spec(sensor, tolerance)
    with console.status("starting") as status:
        started = time.perf_counter()

        def step(message: str) -> None:
            console.log(message)
            status.update(f"{message} ({time.perf_counter() - started:.0f} s)")

        result = run_demo(
            output,
            part_name=part,
            units=units,
            spec=spec,
            points_per_profile=points,
            seed=seed,
            step=step,
            roi=roi,
        )
    table = Table(title=f"{part}: scan quality by planner")
    table.add_column("metric")
    for name in result.metrics:
        table.add_column(name, justify="right")
    for label, values in table_rows([m.to_json_dict() for m in result.metrics.values()]):
        table.add_row(label, *values)
    console.print(table)
    console.print(f"report:   {result.report}")
    console.print(
        f"URScript: {result.program} (parses back to the planned poses within "
        f"{result.program_error_m:.1e} m)"
    )
    console.print(f"done in {result.seconds:.0f} s -> {result.out_dir}")


def main() -> None:  # pragma: no cover - console entry for `python -m scanplan`
    app()
    sys.exit(0)
