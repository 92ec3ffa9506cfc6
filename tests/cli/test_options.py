"""Options and the plan file's numbers held to plausible ranges before any work (issue 46):
fixtures counted before any is read, --perturb's and training's magnitudes in their ranges,
each refused in one line naming the option or the file, exit 2, nothing written."""

from __future__ import annotations

import json
import os

import pytest

from helpers import run_cli

HUGE = "1" * 400  # a number float() reads as inf


def assert_refused(result, *fragments: str) -> None:
    assert result.exit_code == 2, (result.exit_code, result.output)
    assert len(result.stderr.splitlines()) == 1 and "Traceback" not in result.output
    for fragment in fragments:
        assert fragment in result.stderr, result.stderr


@pytest.fixture()
def planned(plate_file, tmp_path):
    """A plan of the plate, as JSON with its context."""
    plan = tmp_path / "plan.json"
    result = run_cli("plan", str(plate_file), "--views", "top", "-q", "-o", str(plan))
    assert result.exit_code == 0, result.output
    return plate_file, plan


@pytest.mark.parametrize("command", ["plan", "evaluate"])
def test_thousands_of_fixtures_are_refused_before_any_is_read(plate_file, tmp_path, command):
    out = tmp_path / "out"
    fixtures = [a for _ in range(3000) for a in ("--fixture", str(tmp_path / "none.stl"))]
    args = [str(plate_file), *([str(tmp_path / "plan.json")] if command == "evaluate" else [])]
    result = run_cli(command, *args, "-o", str(out), *fixtures)
    assert_refused(result, "--fixture: fixture files: 3,000 is more than the 100 allowed")
    assert not out.exists()


@pytest.mark.parametrize(
    "args",
    [
        ["evaluate", "PART", "PLAN", "-q"],
        ["place", "PLAN", "--robot", "ur5e"],
        ["view", "PLAN", "-o", "OUT"],
        ["export", "PLAN", "--robot", "ur5e", "-o", "OUT"],
    ],
)
def test_a_plan_recording_thousands_of_fixtures_is_refused_naming_it(planned, tmp_path, args):
    part, plan = planned
    record = json.loads(plan.read_text())
    record["context"]["fixtures"] = ["clamp.stl"] * 10_000
    plan.write_text(json.dumps(record))
    out = tmp_path / "out.html"
    names = {"PART": str(part), "PLAN": str(plan), "OUT": str(out)}
    result = run_cli(*(names.get(a, a) for a in args))
    assert_refused(result, f"plan {plan}: context: fixtures: 10,000 is more than the 100")
    assert not out.exists()


@pytest.mark.parametrize(
    ("command", "field", "value", "said"),
    [
        ("evaluate", "roi", "cube:1", "context: roi 'cube:1': unknown term 'cube:1'"),
        ("defects", "roi", "cube:1", "context: roi 'cube:1': unknown term 'cube:1'"),
        ("evaluate", "table", "tall", "context: table 'tall': expected a height in mm or none"),
    ],
)
def test_a_bad_roi_or_table_in_the_plan_file_is_named_as_the_file_s(
    planned, tmp_path, command, field, value, said
):
    """Text the plan file records is named as its field, not as an option never given;
    the same text given as the option is named as the option. (`defects` builds no cell
    from the table: only the fixtures hide the part from it.)"""
    part, plan = planned
    record = json.loads(plan.read_text())
    record["context"][field] = value
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(record))
    out = tmp_path / "out"
    result = run_cli(command, str(part), str(bad), "-q", "-o", str(out))
    assert_refused(result, f"plan {bad}: {said}")
    assert not out.exists()
    given = run_cli("evaluate", str(part), str(plan), "-q", f"--{field}", value)
    assert given.exit_code == 2 and f"--{field} {value!r}" in given.stderr, given.output


def test_a_fixture_that_is_a_fifo_is_said_so_as_a_fixture(planned, tmp_path):
    part, plan = planned
    fifo = tmp_path / "clamp.stl"
    os.mkfifo(fifo)
    result = run_cli("evaluate", str(part), str(plan), "-q", "--fixture", str(fifo))
    assert_refused(result, f"fixture file {fifo} is a FIFO (named pipe), not a file")


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        (f"place:{HUGE}mm", "the length a number of 400 digits is not in [0, 1000] mm"),
        (f"warp:{HUGE}mm@200mm", "the amplitude a number of 400 digits is not in [0, 1000] mm"),
        ("scale:50%", "the scale error 50% is not in [0, 10] %"),
    ],
)
def test_implausible_perturbations_are_refused_naming_the_term(planned, tmp_path, spec, message):
    part, plan = planned
    out = tmp_path / "report"
    result = run_cli("evaluate", str(part), str(plan), "--perturb", spec, "-o", str(out))
    assert_refused(result, "--perturb term '", message)
    assert len(result.stderr) < 200 and not out.exists()


@pytest.mark.parametrize("scale", ["1e-300", "0.05", "1e5", "nan"])
def test_an_implausible_reward_scale_is_refused_before_training(tmp_path, scale):
    out = tmp_path / "policy"
    result = run_cli("train", "-o", str(out), "--timesteps", "64", "--reward-distance-scale", scale)
    assert_refused(result, "--reward-distance-scale")
    assert not out.exists()
