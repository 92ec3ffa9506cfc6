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

# The order `scanplan --help` lists them in.
app.command("part")(part_cmd)
app.command("scan")(scan_cmd)
app.command("plan")(plan_cmd)
app.command("evaluate")(evaluate_cmd)
app.command("compare")(compare_cmd)
app.command("view")(view_cmd)
app.command("defects")(defects_cmd)
app.command("train")(train_cmd)
app.command("sweep")(sweep_cmd)
app.command("export")(export_cmd)
app.command("place")(place_cmd)
app.command("demo")(demo_cmd)


def main() -> None:  # pragma: no cover - console entry for `python -m scanplan`
    app()
    sys.exit(0)
