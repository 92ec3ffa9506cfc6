"""The `scanplan` command line (SPEC §8): parses, calls the library, prints.

Every user mistake ends as one line on stderr and exit code 2, with no partial output file
(writers in the library are atomic).
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer

app = typer.Typer(
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


PartArg = Annotated[
    str, typer.Argument(help="built-in part name or mesh file (STL/OBJ/PLY/OFF/GLB)")
]
UnitsOpt = Annotated[str, typer.Option("--units", help="units of a mesh file: mm, m or in")]
SensorOpt = Annotated[
    str, typer.Option("--sensor", help="sensor preset name or TOML/YAML datasheet file")
]
OutOpt = Annotated[Path, typer.Option("-o", "--output", help="output file")]


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
    seed: Annotated[int, typer.Option(help="noise seed")] = 0,
    no_noise: Annotated[bool, typer.Option("--no-noise", help="switch noise off")] = False,
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
    the_part = load_part(part, units)
    traj = read_trajectory(trajectory)
    if not traj.scanning.any():
        raise ValueError(f"trajectory {trajectory} has no scanning pose")
    cloud = simulate_cloud(the_part, spec, traj, seed=seed)
    if len(cloud.points_part) == 0:
        raise ValueError(
            f"no valid point: part {part} is outside the sensor's reach along {trajectory}"
        )
    write_ply(cloud, output)
    typer.echo(
        f"{len(cloud.points_part)} points from {int(traj.scanning.sum())} profiles -> {output}"
    )


# ---- plan / evaluate (planners and metrics) ----------------------------------------------
PLANNERS = ("fixed", "geometric", "rl")


def make_planner(name: str, policy: Path | None = None):
    """The planner called `name`; `rl` loads a policy file (or the packaged default)."""
    if name == "fixed":
        from scanplan.planners.fixed import FixedPlanner

        return FixedPlanner()
    if name == "geometric":
        from scanplan.planners.geometric import GeometricPlanner

        return GeometricPlanner()
    if name == "rl":
        try:
            from scanplan.planners.rl import RLPlanner
        except ImportError as exc:
            raise ValueError(f"the rl planner is not available in this install ({exc})") from None
        if policy is not None:
            return RLPlanner.from_file(policy)
        default = getattr(RLPlanner, "default", None)
        if default is None:
            raise ValueError("no default policy ships with this install; pass --policy FILE")
        return default()
    raise ValueError(f"unknown planner {name!r}; use one of {', '.join(PLANNERS)}")


@app.command("plan")
@user_errors
def plan_cmd(
    part: PartArg,
    output: OutOpt,
    planner: Annotated[str, typer.Option(help="fixed, geometric or rl")] = "geometric",
    sensor: SensorOpt = "at-c5-4090cs30-495",
    policy: Annotated[
        Path | None, typer.Option(help="trained policy file for --planner rl")
    ] = None,
    direction: Annotated[str, typer.Option(help="scan direction: x, y or auto")] = "auto",
    overlap: Annotated[float, typer.Option(help="overlap of adjacent passes, [0, 1)")] = 0.2,
    units: UnitsOpt = "mm",
):
    """Plan a scan trajectory over a part; write it as CSV (SPEC §8 columns)."""
    from scanplan.config import load_sensor
    from scanplan.part import load_part
    from scanplan.planners import plan_path
    from scanplan.swaths import plan_swaths
    from scanplan.trajectory import write_csv, write_json

    if output.suffix.lower() not in (".csv", ".json"):
        raise ValueError(f"output {output} must be a .csv or .json file")
    spec = load_sensor(sensor)
    the_part = load_part(part, units)
    the_planner = make_planner(planner, policy)
    swaths = plan_swaths(the_part, spec, direction, overlap)
    traj = plan_path(the_part, spec, the_planner, swaths)
    (write_json if output.suffix.lower() == ".json" else write_csv)(traj, output)
    typer.echo(
        f"{the_planner.name}: {len(swaths)} passes, {int(traj.scanning.sum())} profiles, "
        f"{traj.path_length_mm():.0f} mm, planned in {traj.plan_time_s:.2f} s -> {output}"
    )


@app.command("evaluate")
@user_errors
def evaluate_cmd(
    part: PartArg,
    trajectory: Annotated[Path, typer.Argument(help="trajectory CSV or JSON")],
    as_json: Annotated[bool, typer.Option("--json", help="print one JSON object")] = False,
    output: Annotated[
        Path | None, typer.Option("-o", "--output", help="report directory (PNG maps, metrics)")
    ] = None,
    sensor: SensorOpt = "at-c5-4090cs30-495",
    units: UnitsOpt = "mm",
    points: Annotated[
        int | None, typer.Option("--points", help="sub-sample the fan to N points (faster)")
    ] = None,
    seed: Annotated[int, typer.Option(help="noise seed")] = 0,
):
    """Simulate the scan of a trajectory and report its quality (SPEC §7)."""
    import json

    from scanplan.config import load_sensor
    from scanplan.metrics import evaluate
    from scanplan.part import load_part
    from scanplan.trajectory import atomic_write_text, read_trajectory

    if points is not None and points < 2:
        raise ValueError(f"--points must be >= 2, got {points}")
    spec = load_sensor(sensor)
    the_part = load_part(part, units)
    traj = read_trajectory(trajectory)
    metrics = evaluate(the_part, spec, traj, seed=seed, points_per_profile=points)
    data = metrics.to_json_dict()
    if output is not None:
        from scanplan.report.maps import metrics_table_markdown, plot_error_maps

        plot_error_maps(metrics, output, planner=traj.planner or trajectory.stem)
        atomic_write_text(output / "metrics.json", json.dumps(data, indent=1) + "\n")
        atomic_write_text(
            output / "metrics.md",
            f"# {the_part.name}: {trajectory.name}\n\n"
            + metrics_table_markdown([metrics], [traj.planner or trajectory.stem]),
        )
    if as_json:
        typer.echo(json.dumps(data))
        return
    d, o, s = data["distance_error_mm"], data["orientation_error_deg"], data["spacing_mm"]
    typer.echo(
        f"{data['profiles']} profiles | |distance error| mean {d['mean_abs']:.3f} "
        f"p95 {d['p95_abs']:.3f} mm | orientation mean {o['mean']:.2f} p95 {o['p95']:.2f} deg | "
        f"coverage {data['coverage_fraction']:.1%} | spacing {s['mean']:.3f} mm "
        f"(cv {s['cv']:.3f}, {s['backward_steps']} backward) | reward {data['reward']['mean']:.4f}"
        + (f" -> {output}" if output is not None else "")
    )


# ---- train (RL) --------------------------------------------------------------------------


# ---- export (robot programs) --------------------------------------------------------------
POSE_HELP = "x,y,z in mm then A,B,C in degrees (KUKA intrinsic ZYX: Rz(A) Ry(B) Rx(C))"


@app.command("export")
@user_errors
def export_cmd(
    trajectory: Annotated[Path, typer.Argument(help="trajectory CSV or JSON")],
    output: OutOpt,
    fmt: Annotated[
        str, typer.Option("--format", help="urscript, rapid, krl, ros or csv")
    ] = "urscript",
    tcp: Annotated[str, typer.Option(help=f"flange->sensor TCP: {POSE_HELP}")] = "0,0,0,0,0,0",
    part_pose: Annotated[
        str, typer.Option("--part-pose", help=f"part in the robot base frame: {POSE_HELP}")
    ] = "0,0,0,0,0,0",
    profile_rate: Annotated[
        float, typer.Option(help="sensor profile rate, Hz; scan speed = rate x spacing")
    ] = 200.0,
    spacing: Annotated[float, typer.Option(help="profile spacing on the part, mm")] = 0.5,
    travel_speed: Annotated[float, typer.Option(help="speed between passes, mm/s")] = 250.0,
    robot: Annotated[
        str, typer.Option(help="check reach for ur3e, ur5e or ur10e; 'none' to skip")
    ] = "ur5e",
):
    """Write a robot program (URScript, ABB RAPID, KUKA KRL, ROS 2 YAML or CSV)."""
    from scanplan.export import FORMATS, ExportOptions, export_program, flange_poses, parse_pose_arg
    from scanplan.robot import check_reach
    from scanplan.trajectory import atomic_write_text, read_trajectory

    if fmt not in FORMATS:
        raise ValueError(f"unknown format {fmt!r}; use one of {', '.join(FORMATS)}")
    # KUKA wants the .src file named after its DEF.
    name = output.stem if output.stem.isidentifier() and len(output.stem) <= 24 else ""
    options = ExportOptions(
        part_pose=parse_pose_arg(part_pose),
        tcp=parse_pose_arg(tcp),
        profile_rate_hz=profile_rate,
        delta_s_opt_mm=spacing,
        travel_speed_mm_s=travel_speed,
        program_name=name if name and fmt == "krl" else "scanplan_path",
    )
    traj = read_trajectory(trajectory)
    text = export_program(traj, fmt, options)
    if robot.lower() != "none":
        report = check_reach(flange_poses(traj, options), robot)
        if not report.ok:
            typer.echo(f"warning: {report.summary()}", err=True)
        else:
            typer.echo(report.summary())
    atomic_write_text(output, text)
    typer.echo(f"{fmt}: {len(traj)} poses, scan speed {options.scan_speed:.1f} mm/s -> {output}")


# ---- demo ---------------------------------------------------------------------------------


def main() -> None:  # pragma: no cover - console entry for `python -m scanplan`
    app()
    sys.exit(0)
