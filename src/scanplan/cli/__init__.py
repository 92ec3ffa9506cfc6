"""The `scanplan` command line: parses, calls the jobs, prints. One module per
command group, shared options in `options`; every user mistake ends as one line on stderr and
exit code 2, with no partial output file (`common`; the library's writers are atomic).
"""

from __future__ import annotations

import sys

import typer

from scanplan.cli.common import OneLineErrors
from scanplan.cli.compare import compare_cmd
from scanplan.cli.defects import defects_cmd
from scanplan.cli.demo import demo_cmd
from scanplan.cli.evaluate import evaluate_cmd, scan_cmd
from scanplan.cli.help_text import Command
from scanplan.cli.parts import part_cmd
from scanplan.cli.plan import plan_cmd
from scanplan.cli.robot import export_cmd, place_cmd
from scanplan.cli.training import sweep_cmd, train_cmd
from scanplan.cli.view import view_cmd

__all__ = ["app", "main"]

app = typer.Typer(
    cls=OneLineErrors,
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Plan, simulate, evaluate and export laser-profilometer scan trajectories.",
)

# The order `scanplan --help` lists them in, each with the one line it shows there (the
# command's own --help gives the whole story).
COMMANDS = (
    ("part", part_cmd, "Write a built-in part (door, drone, training-piece) as a mesh file."),
    ("scan", scan_cmd, "Simulate a plan's scan and write the point cloud (PLY)."),
    ("plan", plan_cmd, "Plan the sensor's path over a part (or a folder or list of parts)."),
    (
        "evaluate",
        evaluate_cmd,
        "Simulate a plan's scan and judge it: in-spec coverage, errors, cycle time, robustness.",
    ),
    ("compare", compare_cmd, "Plan and judge several parts into one table, hardest first."),
    ("view", view_cmd, "Write a plan's 3-D page (HTML): part, passes, moves and the arm."),
    ("defects", defects_cmd, "Inject seeded defects and measure which a plan finds (POD)."),
    ("train", train_cmd, "Train the pass agent with PPO and write a policy."),
    (
        "sweep",
        sweep_cmd,
        "Train seeds x settings on Dask and compare the policies on unseen parts.",
    ),
    ("export", export_cmd, "Write the robot program once the arm is shown to fly the plan."),
    ("place", place_cmd, "Find where to put the part so the arm flies every pose."),
    ("demo", demo_cmd, "The main job on the door: three planners, report, a RAPID program."),
)
for name, command, summary in COMMANDS:
    app.command(name, cls=Command, short_help=summary)(command)


def main() -> None:  # pragma: no cover - console entry for `python -m scanplan`
    app()
    sys.exit(0)
