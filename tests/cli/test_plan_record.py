"""One plan, one answer: every command reads the plan the same way. The part and its units,
the sensor, the arm and the cycle time come from the plan; what differs is refused in one
line or said."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from helpers import run_cli

SENSOR_200 = """name = "short200"
working_distance_mm = 200
z_range_mm = 100
fov_deg = 40
points_per_profile = 256
z_resolution_um = 2
triangulation_angle_deg = 25
"""


@pytest.fixture(scope="module")
def inch_plan(tmp_path_factory) -> tuple[Path, Path, Path]:
    """A 10 x 6 inch plate (a file in inches) planned with a 200 mm sensor: (part, plan, dir)."""
    import trimesh

    d = tmp_path_factory.mktemp("record")
    plate = trimesh.creation.box((10.0, 6.0, 0.4))
    plate.apply_translation((0, 0, -0.2))
    part = d / "plate_in.stl"
    plate.export(part)
    (d / "s200.toml").write_text(SENSOR_200)
    plan = d / "plan.csv"
    result = run_cli(
        "plan", str(part), "--units", "in", "--sensor", str(d / "s200.toml"), "--planner",
        "fixed", "--views", "top", "-q", "-o", str(plan),
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    return part, plan, d


def test_a_recorded_part_not_found_from_here_is_asked_for_in_one_line(
    inch_plan, tmp_path, monkeypatch
):
    part, _, d = inch_plan
    monkeypatch.chdir(d)  # planned with the part's path as typed there: relative
    planned = run_cli(
        "plan", part.name, "--units", "in", "--planner", "fixed", "--views", "top", "-q",
        "-o", "relative.csv",
    )  # fmt: skip
    assert planned.exit_code == 0, planned.output
    monkeypatch.chdir(tmp_path)  # another folder: that path leads nowhere from here
    plan = str(d / "relative.csv")
    result = run_cli("evaluate", plan, "--points", "64")
    assert result.exit_code == 2 and result.stderr.count("\n") == 1, result.output
    assert "records its part as given when it was planned" in result.stderr
    assert "Traceback" not in result.output
    given = run_cli("evaluate", str(part), plan, "--points", "64")
    assert given.exit_code == 0, given.output


def _cycle(output: str) -> str:
    return re.search(r"cycle time ([0-9.]+) s", output).group(1)


def test_evaluate_takes_the_part_and_its_units_from_the_plan(inch_plan):
    part, plan, _ = inch_plan
    given = run_cli("evaluate", str(part), str(plan), "--points", "64", "--json")
    alone = run_cli("evaluate", str(plan), "--points", "64", "--json")  # the plan's own part
    assert given.exit_code == 0 and alone.exit_code == 0, given.output + alone.output
    figures = [json.loads(r.stdout) for r in (given, alone)]
    for data in figures:
        data.pop("eval_time_s", None)  # the only figure that is the machine's
    assert figures[0] == figures[1]
    assert 0.5 < figures[0]["in_spec_coverage"] <= 1.0  # not the 0 % of a part read in mm


def test_another_part_or_other_units_is_one_line(inch_plan, tmp_path):
    part, plan, _ = inch_plan
    result = run_cli("evaluate", str(part), str(plan), "--units", "mm")
    assert result.exit_code == 2 and result.output.count("\n") == 1
    assert "was made with --units in" in result.output
    result = run_cli("evaluate", "drone", str(plan))
    assert result.exit_code == 2 and result.output.count("\n") == 1
    assert "is not the part plan" in result.output and "--other-part" in result.output
    result = run_cli("scan", "drone", str(plan), "-o", str(tmp_path / "c.ply"))
    assert result.exit_code == 2 and not (tmp_path / "c.ply").exists()
    result = run_cli("defects", "drone", str(plan), "--trials", "1")
    assert result.exit_code == 2 and "is not the part plan" in result.output


def test_the_program_is_the_plans_sensor_and_its_cycle_time_the_plans(inch_plan):
    _, plan, d = inch_plan
    planned = run_cli("evaluate", str(plan), "--points", "64")
    program = d / "p.script"
    exported = run_cli("export", str(plan), "--robot", "none", "-o", str(program))
    assert exported.exit_code == 0, exported.output
    assert "TCP standoff 200 mm" in program.read_text()  # the plan's sensor, not the default
    assert _cycle(exported.output) == _cycle(planned.output)
    recorded = re.search(r"# cycle_time_s: ([0-9.]+)", plan.read_text()).group(1)
    assert f"{float(recorded):.1f}" == _cycle(planned.output)
    # A program flown faster than planned says its own figure, and that it differs.
    faster = run_cli(
        "export", str(plan), "--robot", "none", "--travel-speed", "400", "-o", str(program)
    )
    assert faster.exit_code == 0 and "the plan's cycle time was" in faster.output
    assert "--travel-speed 400 (planned: " in faster.output


def test_no_format_follows_the_file_and_a_mismatch_writes_nothing(inch_plan):
    _, plan, d = inch_plan
    krl = d / "p.src"
    result = run_cli("export", str(plan), "--robot", "ur5e", "-o", str(krl))
    assert result.exit_code == 2 and "not the language of ur5e's controller" in result.output
    assert not krl.exists()
    result = run_cli("export", str(plan), "--robot", "none", "--format", "urscript", "-o", str(krl))
    assert result.exit_code == 2 and "a .src file holds krl" in result.output
    assert not krl.exists()
