"""`scanplan compare` and --require on plan and evaluate, end to end on two small parts."""

from __future__ import annotations

import csv
import io
import json

import pytest
import trimesh
from typer.testing import CliRunner

from scanplan.cli import app

runner = CliRunner()
FAST = ["--points", "48", "--planner", "fixed", "-q"]


@pytest.fixture(scope="module")
def parts(tmp_path_factory):
    """A list of two parts: a 300 mm plate in mm, and a 6 x 4 x 1 inch block in inches."""
    folder = tmp_path_factory.mktemp("parts")
    trimesh.creation.box((300.0, 200.0, 10.0)).export(folder / "plate.stl")
    trimesh.creation.box((6.0, 4.0, 1.0)).export(folder / "block.stl")
    (folder / "parts.txt").write_text("plate.stl\nblock.stl in  # inches\n")
    return folder


@pytest.fixture(scope="module")
def compared(parts):
    out = parts / "cmp.json"
    result = runner.invoke(app, ["compare", str(parts / "parts.txt"), *FAST, "-o", str(out)])
    assert result.exit_code == 0, result.output
    return json.loads(out.read_text()), result.stdout


def test_compare_lists_each_part_in_its_units_hardest_first(compared, parts):
    data, printed = compared
    rows = data["rows"]
    assert [r["part"] for r in rows] in (["plate.stl", "block.stl"], ["block.stl", "plate.stl"])
    in_spec = [r["figures"]["in-spec"] for r in rows]
    assert in_spec == sorted(in_spec) and all(0.5 < v <= 1.0 for v in in_spec)
    # The block was read in inches: 152 mm long, not 6 mm (which no plan could raster).
    assert all(r["error"] is None and r["figures"]["cycle"] > 1.0 for r in rows)
    assert set(data["figures"]) == {"in-spec", "ceiling", "cycle", "a90"}
    # The terminal shows the same values, under the same names, in the same order.
    lines = printed.splitlines()
    assert lines[0].split()[:6] == ["part", "planner", "views", "in-spec", "ceiling", "cycle"]
    for row, line in zip(rows, lines[1:3], strict=True):
        assert line.startswith(row["part"]) and f"{row['figures']['in-spec']:.1%}" in line
    assert "in-spec: in-spec coverage" in printed


def test_every_format_holds_the_same_table(compared, parts):
    data, _ = compared
    rows = data["rows"]
    base = ["compare", str(parts / "parts.txt"), *FAST]
    for suffix in ("csv", "md", "html"):
        out = parts / f"cmp.{suffix}"
        assert runner.invoke(app, [*base, "-o", str(out)]).exit_code == 0
    table = list(csv.DictReader(io.StringIO((parts / "cmp.csv").read_text())))
    assert [t["part"] for t in table] == [r["part"] for r in rows]
    assert [float(t["in-spec"]) for t in table] == pytest.approx(
        [r["figures"]["in-spec"] for r in rows], rel=1e-5
    )
    md = (parts / "cmp.md").read_text()
    assert "| part | planner | views | in-spec |" in md
    assert f"| {rows[0]['part']} | fixed |" in md
    page = (parts / "cmp.html").read_text()
    assert page.startswith("<!doctype html>") and rows[1]["part"] in page


def test_require_passes_fails_with_exit_3_and_names_each_criterion(parts):
    base = ["compare", str(parts / "plate.stl"), *FAST]
    ok = runner.invoke(app, [*base, "--require", "in-spec>=0.5,cycle<=1h"])
    assert ok.exit_code == 0, ok.output
    assert ok.stdout.splitlines()[1].rstrip().endswith("pass")
    out = parts / "fail.json"
    bad = runner.invoke(app, [*base, "--require", "in-spec>=0.5,cycle<=1s", "-o", str(out)])
    assert bad.exit_code == 3
    assert "FAIL cycle<=1s" in bad.stdout and "1 of 1 rows fail --require" in bad.stderr
    row = json.loads(out.read_text())["rows"][0]
    assert row["pass"] is False
    assert [(v["figure"], v["pass"]) for v in row["verdicts"]] == [
        ("in-spec", True),
        ("cycle", False),
    ]


def test_a_part_that_fails_is_one_error_row_and_the_rest_still_run(parts):
    (parts / "gone.txt").write_text("gone.stl\n")
    result = runner.invoke(
        app, ["compare", str(parts / "plate.stl"), str(parts / "gone.txt"), *FAST]
    )
    assert result.exit_code == 1
    first, second = result.stdout.splitlines()[1:3]
    assert first.startswith("gone.stl") and "error: part file" in first
    assert second.startswith("plate.stl") and "%" in second
    assert result.stderr.strip() == "error: 1 of 2 rows failed"


@pytest.mark.parametrize(
    "args, message",
    [
        (["--require", "p5>=0.8"], "needs --perturb"),
        (["--require", "pod-a90<=0.1"], "needs --defects"),
        (["--require", "in-spec>0.9;"], "expected NAME>=VALUE"),
        (["-o", "t.xlsx"], "--format 'xlsx'"),
        (["--format", "csv"], "give -o FILE too"),
        (["missing.stl"], "part file missing.stl does not exist"),
    ],
)
def test_bad_options_are_one_line_before_any_work(parts, tmp_path, args, message):
    result = runner.invoke(app, ["compare", str(parts / "plate.stl"), *FAST, *args])
    assert result.exit_code == 2 and message in result.stderr
    assert result.stderr.count("\n") == 1 and result.stdout == ""


def test_plan_and_evaluate_hold_their_figures_to_require(parts, tmp_path):
    plan = tmp_path / "p.json"
    args = ["plan", str(parts / "plate.stl"), "--planner", "fixed", "-o", str(plan)]
    result = runner.invoke(app, [*args, "--require", "cycle<=1s"])
    assert result.exit_code == 3 and "FAIL: cycle time" in result.stdout and plan.is_file()
    result = runner.invoke(app, [*args, "--require", "in-spec>=0.9"])
    assert result.exit_code == 2 and "is measured by evaluate or compare" in result.stderr
    result = runner.invoke(app, [*args, "--require", "arm-cost<=0.05"])
    assert result.exit_code == 2 and "needs --robot" in result.stderr
    evaluate = ["evaluate", str(plan), "--points", "48", "--json"]
    result = runner.invoke(app, [*evaluate, "--require", "in-spec>=0.5,cycle<=1s"])
    assert result.exit_code == 3
    data = json.loads(result.stdout)
    assert data["pass"] is False
    assert [v["pass"] for v in data["verdicts"]] == [True, False]
    assert data["verdicts"][0]["value"] == data["in_spec_coverage"]
    result = runner.invoke(app, [*evaluate, "--require", "worst>=0.5"])
    assert result.exit_code == 2 and "needs --perturb" in result.stderr
    report = tmp_path / "report"
    result = runner.invoke(app, [*evaluate[:-1], "-o", str(report), "--require", "in-spec>=0.5"])
    assert result.exit_code == 0 and "verdict: pass" in result.stdout
    assert "Verdict: pass" in (report / "report.html").read_text()
