"""`--help` reads as prose: no line broken mid-sentence, placeholders that name a value,
defaults as values; and evaluate's old --views still works, with a warning."""

from __future__ import annotations

import json
import re

import pytest
from typer.testing import CliRunner

from helpers import run_cli
from scanplan.cli import COMMANDS, app

HELPS = [[], *([name] for name, _, _ in COMMANDS)]


def _help(args: list[str], columns: int) -> str:
    result = CliRunner().invoke(app, [*args, "--help"], env={"COLUMNS": str(columns)})
    assert result.exit_code == 0, result.output
    return result.output


@pytest.mark.parametrize("args", HELPS, ids=lambda a: " ".join(a) or "scanplan")
def test_no_help_line_is_broken_mid_sentence(args):
    """Wide enough for every paragraph, each one is one line: a text hard-wrapped in the
    source would show as a line that stops short, its sentence going on below."""
    text = _help(args, 1000)
    panel_rows = [line[1:].rstrip("│ ") for line in text.splitlines() if line.startswith("│")]
    # A row goes on below its first line only if its text was broken: the name columns of a
    # continuation row are blank.
    broken = [row for row in panel_rows if row.startswith(" " * 8)]
    assert not broken, broken
    prose = text.split("╭")[0].splitlines()[2:]  # the description under the usage line
    for line in filter(str.strip, prose):
        assert line.rstrip().endswith((".", ")", ":")), repr(line)


@pytest.mark.parametrize("args", HELPS, ids=lambda a: " ".join(a) or "scanplan")
def test_help_fits_80_columns_and_names_values_not_python_types(args):
    text = _help(args, 80)
    assert max(len(line) for line in text.splitlines()) <= 80
    assert not re.search(r"<(bool|str|int|float|path)>|list\[", text), text


def test_defaults_are_values_not_formulas():
    for command in ("plan", "evaluate", "demo"):
        text = " ".join(_help([command], 1000).split())
        assert "default 12.5,15" in text and "Z_r/20" not in text
    assert "default: all of the sensor's (4096" in " ".join(_help(["evaluate"], 1000).split())


def test_every_output_option_says_file_or_folder():
    for name, _, _ in COMMANDS:
        if name == "place":  # prints a pose, writes nothing
            continue
        line = next(x for x in _help([name], 1000).splitlines() if "--output" in x)
        assert "output file" in line or "output folder" in line, (name, line)


def test_evaluate_surface_and_its_old_name(plate_and_trajectory):
    plate, traj = plate_and_trajectory
    base = ["evaluate", str(plate), str(traj), "--points", "16", "--json", "-q"]
    new = run_cli(*base, "--surface", "top")
    old = run_cli(*base, "--views", "top")
    assert new.exit_code == old.exit_code == 0, (new.output, old.output)
    assert "--views is now --surface" in old.stderr and "--views" not in new.stderr
    figures = [
        {k: v for k, v in json.loads(r.stdout).items() if k != "eval_time_s"} for r in (new, old)
    ]
    assert figures[0] == figures[1]
    hemisphere = json.loads(run_cli(*base, "--surface", "hemisphere").stdout)
    assert (
        hemisphere["surface"]["name"] == "hemisphere" != json.loads(new.stdout)["surface"]["name"]
    )
    for bad in (["--surface", "side"], ["--surface", "top", "--views", "top"]):
        result = run_cli(*base, *bad)
        assert result.exit_code == 2 and len(result.stderr.strip().splitlines()) <= 2, result.output
        assert "--surface" in result.stderr
