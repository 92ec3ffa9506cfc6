"""Options declared once for every command that takes them: part, sensor, tolerance, seed,
poses, and the training group `train` and `sweep` share; plus the checks and parsers of
their values.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer

from scanplan.core.limits import (
    ACTION,
    MAX_BC_SAMPLES,
    MAX_FIXTURES,
    MAX_SEED,
    ORIENTATION_ERROR_DEG,
    POSITION_MM,
    REWARD_DISTANCE_SCALE_MM,
    TCP_MM,
    TOLERANCE_MM,
    Limit,
    check_count,
)
from scanplan.core.quantities import ScanSpec
from scanplan.core.sensor_spec import SensorSpec


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
        f"{'(' if lo_open else '['}{_num(lo)}, {_num(hi)}{')' if hi_open else ']'}"
        if lo is not None and hi is not None
        else f"{'>' if lo_open else '>='} {_num(lo)}"
        if lo is not None
        else f"{'<' if hi_open else '<='} {_num(hi)}"
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


def _num(x: float) -> str:
    """A bound as a user types it: whole numbers in full (4294967295, not 4.29497e+09)."""
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e16 else f"{x:g}"


def within(limit: Limit) -> Callable[[Any], Any]:
    """The `bounded` callback of one of `scanplan.core.limits`' ranges."""
    return bounded(limit.lo, limit.hi, lo_open=limit.lo_open, hi_open=limit.hi_open)


def pose_option(tcp: bool) -> Callable[[str | None], str | None]:
    """The callback of --tcp (`tcp`) or --part-pose: six numbers in their ranges, checked
    before any work (None: not given); Click names the option in the error."""

    def check(value: str | None) -> str | None:
        # Deferred: export loads the writers of every dialect.
        from scanplan.robot.export import parse_pose_arg

        if value is None:
            return None
        try:
            parse_pose_arg(value, TCP_MM if tcp else POSITION_MM)
        except ValueError as exc:
            raise typer.BadParameter(str(exc)) from None
        return value

    return check


def pose_list_option(value: str | None) -> str | None:
    """The callback of plan's --tcp: one pose, or several separated by ';' (brackets to
    choose among), each checked as `pose_option`'s."""
    if value is None:
        return None
    check = pose_option(tcp=True)
    for one in value.split(";"):
        check(one.strip())
    return value


def fixture_count(value: list[str] | None) -> list[str] | None:
    """--fixture, counted before any file is read (thousands crash the ray casts)."""
    try:
        check_count(len(value or ()), MAX_FIXTURES, "fixture files", "a cell holds a few clamps")
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None
    return value


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
    if not (TOLERANCE_MM.contains(mm) and ORIENTATION_ERROR_DEG.contains(deg)):
        raise ValueError(
            f"--tolerance {text!r}: expected MM,DEG with MM in {TOLERANCE_MM} and DEG in "
            f"{ORIENTATION_ERROR_DEG}, e.g. 12.5,15"
        )
    return {"tol_distance_mm": mm, "tol_angle_rad": math.radians(deg)}


def scan_spec(sensor: str, tolerance: str | None = None) -> ScanSpec:
    """The ScanSpec of the --sensor and --tolerance options."""
    # Deferred: config reads TOML/YAML datasheets.
    from scanplan.core.sensor_files import load_sensor

    tol = parse_tolerance(tolerance)  # before the sensor file: the cheaper check first
    return ScanSpec(load_sensor(sensor), **tol)


SEED_CHECK = bounded(0, MAX_SEED)
# The defaults --help states as values.
_DEFAULT_SPEC = ScanSpec()
POSITIVE = bounded(0, lo_open=True)
POINTS_CHECK = bounded(2, SensorSpec.MAX_POINTS)

# ---- part, sensor, output -----------------------------------------------------------------
PartArg = Annotated[
    str, typer.Argument(help="built-in part name, mesh file (STL/OBJ/PLY/OFF/GLB) or STEP file")
]
UnitsOpt = Annotated[
    str,
    typer.Option(
        "--units",
        metavar="UNIT",
        help="units of a mesh file: mm, m or in (a STEP file carries its own)",
    ),
]
PlannedPartOpt = Annotated[
    str | None,
    typer.Option(
        "--part",
        help="the part the arm's links are checked against (built-in name, mesh or STEP "
        "file); default: the one the plan records",
    ),
]
PlannedUnitsOpt = Annotated[
    str | None,
    typer.Option(
        "--units",
        metavar="UNIT",
        help="units of --part's mesh file: mm, m or in; default: the plan's",
    ),
]
RoiOpt = Annotated[
    str | None,
    typer.Option(
        "--roi",
        metavar="SPEC",
        help="region of interest: box:x0,y0,z0,x1,y1,z1 (mm), +z:30 (a normal cone; any of "
        "±x ±y ±z or n:X,Y,Z:DEG), body:I (the I-th connected body); ';' joins terms (AND)",
    ),
]
# Default: scanplan.core.sensor_spec.DEFAULT_SENSOR (Typer wants an Annotated option's
# default on the parameter, not here).
SensorOpt = Annotated[
    str,
    typer.Option(
        "--sensor", metavar="SENSOR", help="sensor preset name or TOML/YAML datasheet file"
    ),
]
ToleranceOpt = Annotated[
    str | None,
    typer.Option(
        "--tolerance",
        metavar="MM,DEG",
        help="in-spec tolerance: how far a point may lie from the working distance (mm) and "
        "how far the beam may turn from the surface normal (degrees); default "
        f"{_num(_DEFAULT_SPEC.tolerance_mm)},{_num(math.degrees(_DEFAULT_SPEC.tol_angle_rad))} "
        "for the default sensor (a twentieth of a sensor's measuring range, and 15°), or what "
        "the plan records",
    ),
]
SeedOpt = Annotated[
    int, typer.Option(help="seed of the simulated noise, an integer >= 0", callback=SEED_CHECK)
]
QuietOpt = Annotated[
    bool, typer.Option("--quiet", "-q", help="no progress bar (none either off a terminal)")
]
TrajectoryArg = Annotated[
    Path, typer.Argument(metavar="PLAN", help="the plan file (CSV or JSON) `plan` wrote")
]
PartAndPlanArg = Annotated[
    list[str],
    typer.Argument(
        metavar="[PART] PLAN",
        help="the part (built-in name, mesh or STEP file; default: the one the plan records, "
        "in its units) and the plan file (CSV or JSON)",
        show_default=False,
    ),
]


def surface_choice(surface: str | None, views: str | None, command: str) -> tuple[str | None, str]:
    """--surface top|hemisphere, or its old name --views top|auto, as the judged context's
    view mode (top or auto; None: the plan's), and the warning to print once the command has
    done its work ('' for --surface): a command that fails says one line, its error."""
    warning = ""
    if views is not None:
        if surface is not None:
            raise ValueError("give --surface only (--views is its old name)")
        surface = "hemisphere" if views == "auto" else views
        warning = (
            f"warning: {command} --views is now --surface (top or hemisphere); --views will go"
        )
    if surface is None:
        return None, warning
    if surface not in ("top", "hemisphere"):
        option = "--surface" if views is None else "--views (now --surface)"
        raise ValueError(f"unknown {option} {surface!r}; use top or hemisphere")
    return ("auto" if surface == "hemisphere" else "top"), warning


def part_and_plan(values: list[str]) -> tuple[str | None, Path]:
    """[PART] PLAN as given: (the part, or None for the plan's own, and the plan file)."""
    if len(values) not in (1, 2):
        raise ValueError(f"expected [PART] PLAN, got {len(values)} arguments")
    return (values[0] if len(values) == 2 else None), Path(values[-1])


Full3dOpt = Annotated[
    bool,
    typer.Option(
        "--full-3d",
        help="report.html's 3-D views with every face of the part and every sampled point, "
        "pictures at full size (tens of MB for a large part; by default a few MB)",
    ),
]

# ---- poses (export, place) ----------------------------------------------------------------
POSE_HELP = (
    "x,y,z in mm then A,B,C in degrees, rotations about Z, then the new Y, then the new X "
    "(KUKA's A,B,C)"
)
TcpOpt = Annotated[
    str | None,
    typer.Option(
        metavar="POSE",
        help=f"the sensor's pose on the robot's flange: {POSE_HELP}; default: the plan's, else "
        "the flange itself",
        callback=pose_option(tcp=True),
    ),
]
PlanTcpOpt = Annotated[
    str | None,
    typer.Option(
        "--tcp",
        metavar="POSE[;POSE...]",
        help=f"the sensor's pose on the robot's flange: {POSE_HELP}; several separated by ';' "
        "(brackets, e.g. straight and angled: '0,0,90,0,0,0;0,0,90,0,30,0'): each is placed "
        "and judged, and the plan is made with the one the arm flies most of the scan with; "
        "default: the flange itself",
        callback=pose_list_option,
    ),
]
PartPoseOpt = Annotated[
    str | None,
    typer.Option(
        "--part-pose",
        metavar="POSE",
        help=f"the part's pose in the robot's base frame: {POSE_HELP}",
        callback=pose_option(tcp=False),
    ),
]

PositionerOpt = Annotated[
    str | None,
    typer.Option(
        "--positioner",
        metavar="NAME|FILE.toml",
        help="a turntable the part sits on, turned view by view so the arm flies each view "
        "from its good side: turntable (a 1 m-class turntable beside the arm, placed by the "
        "tool) or a TOML file with a [turntable] (and/or [track]) table; needs --robot",
    ),
]
TrackOpt = Annotated[
    float | None,
    typer.Option(
        "--track",
        metavar="LENGTH_MM",
        help="a linear track under the arm, this long (mm), its direction chosen by the tool: "
        "the arm rides with the sensor along it; on the floor beside the table, or overhead "
        "(the arm hung upside down from a gantry) when that flies clearly more; a positioner "
        'file\'s [track] mount = "floor" fixes it; needs --robot',
    ),
]

# ---- training (train, sweep) --------------------------------------------------------------
# Each declared once; training.training_config turns them into the trainer's config.
NEnvsOpt = Annotated[
    int,
    typer.Option("--n-envs", help="parallel environments, 1 to 1024", callback=bounded(1, 1024)),
]
StateOpt = Annotated[str, typer.Option(help="paper (P, θ, D, α, Δs) | no-position | lookahead")]
EnvVersionOpt = Annotated[
    str, typer.Option("--env", help="v0 (the paper's) | v1 (with roll: Δφ, φ and β)")
]
ProceduralOpt = Annotated[
    int,
    typer.Option(
        help="also train on N randomized procedural parts, 0 to 1000", callback=bounded(0, 1000)
    ),
]
FanPointsOpt = Annotated[
    int | None,
    typer.Option(
        help=f"pixel columns simulated per profile in training, 2 to {SensorSpec.MAX_POINTS} "
        "(default: 128)",
        callback=POINTS_CHECK,
    ),
]
LogStdInitOpt = Annotated[
    str, typer.Option(help="initial log std: one value, or Δy,Δz,Δθ (SB3 default 0)")
]
InitAdvanceOpt = Annotated[
    float | None,
    typer.Option(
        help="initial mean advance action Δy, -1 to 1 (0.5 advances one planned profile "
        "spacing); default: none",
        callback=within(ACTION),
    ),
]
StartOffsetOpt = Annotated[
    str,
    typer.Option(
        help="random start error of each episode, MM,DEG: depth along the beam U(-MM, MM) and "
        "pitch U(-DEG, DEG) off the aligned start (beyond the paper, which is silent on the "
        "start; 0,0 = the aligned start)"
    ),
]
RewardDistanceScaleOpt = Annotated[
    float | None,
    typer.Option(
        help="the distance reward's scale in mm, the depth error it charges -1 (a deviation "
        "from the paper, whose half measuring range, 125 mm for the default sensor, leaves a "
        "training piece's relief in the reward's flat bottom; default: that half range), "
        f"{_num(REWARD_DISTANCE_SCALE_MM.lo)} to {_num(REWARD_DISTANCE_SCALE_MM.hi)}",
        callback=within(REWARD_DISTANCE_SCALE_MM),
    ),
]
PitchPivotOpt = Annotated[
    str | None,
    typer.Option(
        help="where a pitch step turns: sensor (its origin; the paper's model, when not "
        "given) | footprint (one working distance along the beam, so pitching does not swing "
        "the footprint; beyond the paper, recorded in policy.json)"
    ),
]
TrainPerturbOpt = Annotated[
    str | None,
    typer.Option(
        "--perturb",
        metavar="SPEC",
        help="train for a part that is not the CAD: each episode draws its own placement "
        "error, as-built warp and scale, e.g. 'place:5mm,2deg;warp:1mm@200mm' (each a "
        "standard deviation, as evaluate --perturb takes them); the pass is the CAD's, the "
        "profiles the part's as it is (beyond the paper)",
        show_default=False,
    ),
]
TrainNoiseOpt = Annotated[
    bool, typer.Option("--noise", help="train with the sensor's depth noise (default: without)")
]
BcSamplesOpt = Annotated[
    int,
    typer.Option(
        help="warm start: first imitate the feedback (proportional) controller on N states",
        callback=bounded(0, MAX_BC_SAMPLES),
    ),
]
TableOpt = Annotated[
    str | None,
    typer.Option(
        "--table",
        metavar="Z|none",
        help="the table under the part: its height Z in part coordinates (mm), or none for a "
        "part held in the air; default: at the part's lowest point",
        show_default=False,
    ),
]
FixtureOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--fixture",
        metavar="FILE",
        help=(
            "a fixture mesh in part coordinates (repeatable): kept clear like the part; it "
            "hides what it covers from the laser and the camera"
        ),
        show_default=False,
        callback=fixture_count,
    ),
]
RequireOpt = Annotated[
    str | None,
    typer.Option(
        "--require",
        help="criteria the result must meet, comma-separated, e.g. "
        "'in-spec>=0.9,cycle<=120s,p5>=80%' (figures: in-spec, ceiling, of-ceiling, coverage, "
        "arm-cost, cycle, p5, worst, a90, pod-a90, collisions; see docs/compare.md); each is "
        "printed pass or FAIL, and a failure ends with exit code 3",
        show_default=False,
    ),
]
