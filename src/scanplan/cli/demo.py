"""`scanplan demo`: the main job (three planners on a part, the table, the report and a robot
program), shown as it runs and summed up as a table.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from scanplan.cli.common import user_errors
from scanplan.cli.options import (
    POINTS_CHECK,
    Full3dOpt,
    RoiOpt,
    SeedOpt,
    SensorOpt,
    ToleranceOpt,
    UnitsOpt,
    scan_spec,
)
from scanplan.core.sensor_spec import DEFAULT_SENSOR, DEMO_POINTS, SensorSpec

if TYPE_CHECKING:
    from rich.console import Console

    from scanplan.jobs.demo import DemoResult

DemoDirOpt = Annotated[
    Path,
    typer.Option(
        "-o",
        "--output",
        metavar="FOLDER",
        help="output folder: report.html, maps, metrics, the plans and the robot program",
    ),
]
DemoPartOpt = Annotated[str, typer.Option(metavar="PART", help="built-in part or mesh file")]
DemoPointsOpt = Annotated[
    int,
    typer.Option(
        "--points",
        help=f"pixel columns simulated per profile, 2 to {SensorSpec.MAX_POINTS} (all "
        f"{SensorSpec().points_per_profile} of the default sensor take minutes); to repeat a "
        "figure, evaluate OUTPUT/trajectory_NAME.csv --points with this number and --surface "
        "hemisphere",
        callback=POINTS_CHECK,
    ),
]


@user_errors
def demo_cmd(
    output: DemoDirOpt = Path("out/demo"),
    part: DemoPartOpt = "door",
    units: UnitsOpt = "mm",
    sensor: SensorOpt = DEFAULT_SENSOR,
    points: DemoPointsOpt = DEMO_POINTS,
    seed: SeedOpt = 0,
    tolerance: ToleranceOpt = None,
    roi: RoiOpt = None,
    full_3d: Full3dOpt = False,
):
    """The main job: three planners on a part (the door by default), the table, maps, an
    HTML report and the rl plan as a RAPID program for an IRB 2400 that flies it (the part
    placed, what the arm cannot fly given up, checked as export checks)."""
    # Deferred: the demo loads the whole library (torch, matplotlib, plotly).
    from rich.console import Console

    from scanplan.jobs.demo import run_demo

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
            full_3d=full_3d,
        )
    print_summary(console, part, result)


def print_summary(console: Console, part: str, result: DemoResult) -> None:
    """The planners side by side, then where the report and the program went."""
    # Deferred: as in demo_cmd.
    from rich.table import Table

    from scanplan.judging.report.table import table_rows

    table = Table(title=f"{part}: scan quality by planner")
    table.add_column("metric")
    for name in result.metrics:
        table.add_column(name, justify="right")
    for label, values in table_rows([m.to_json_dict() for m in result.metrics.values()]):
        table.add_row(label, *values)
    console.print(table)
    console.print(f"report:   {result.report}")
    console.print(result.robot_line)
    console.print(
        f"program:  {result.program} (parses back to the fitted plan's poses within "
        f"{result.program_error_m:.1e} m)"
    )
    console.print(f"done in {result.seconds:.0f} s -> {result.out_dir}")
