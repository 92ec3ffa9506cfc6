"""The main job end to end, on the training piece to keep CI short (the door is `make demo`)."""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import replace

import numpy as np
import pytest
from typer.testing import CliRunner

import scanplan.jobs.demo
from scanplan.cli import app
from scanplan.core.plan_file import read_csv, read_json
from scanplan.core.quantities import ScanSpec
from scanplan.jobs.second_process import SecondProcess
from scanplan.robot.export import ExportOptions, parse_program
from scanplan.robot.export.common import plan_motion

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    result = CliRunner().invoke(
        app,
        ["demo", "--part", "training-piece", "--points", "96", "-o", str(out)],
        terminal_width=200,
    )
    assert result.exit_code == 0, result.output
    return out, result.output


def test_demo_writes_every_output(demo):
    out, _ = demo
    for name in (
        "report.html",
        "scan_rl.mod",
        "trajectory_rl_irb2400.json",
        "metrics.json",
        "distance_error_maps.png",
        "orientation_error_maps.png",
        "trajectory_fixed.csv",
        "trajectory_geometric.csv",
        "trajectory_rl.csv",
    ):
        assert (out / name).is_file(), name
    page = (out / "report.html").read_text()
    assert all(planner in page for planner in ("fixed", "geometric", "rl"))


def test_printed_table_matches_the_report(demo):
    out, printed = demo
    metrics = json.loads((out / "metrics.json").read_text())
    page = (out / "report.html").read_text()
    for label, key in (
        ("mean |distance error| (mm)", ("distance_error_mm", "mean_abs")),
        ("mean orientation error (°)", ("orientation_error_deg", "mean")),
    ):
        fmt = "{:.3f}" if "mm" in label else "{:.2f}"
        values = [fmt.format(metrics[p][key[0]][key[1]]) for p in ("fixed", "geometric", "rl")]
        row = next(line for line in printed.splitlines() if label in line)
        assert re.findall(r"-?\d+\.\d+", row) == values
        html_row = re.search(re.escape(label.replace("|", "|")) + r"</th>(.*?)</tr>", page)
        assert html_row is not None
        assert re.findall(r"<td>(.*?)</td>", html_row.group(1)) == values


def test_the_program_is_the_rl_plan_fitted_to_the_arm(demo):
    out, printed = demo
    planned = read_csv(out / "trajectory_rl.csv")
    fitted = read_json(out / "trajectory_rl_irb2400.json")
    arm = fitted.meta["robot"]
    assert arm["robot"] == "irb2400" and arm["flyable"] and arm["tcp"] == "0,0,90,0,0,0"
    # What the arm gave up is at most what was planned, and said in one line.
    given_up = sum(arm["scanning_poses_given_up"].values())
    assert int(fitted.scanning.sum()) <= int(planned.scanning.sum())
    line = " ".join(printed.split())  # rich wraps long lines
    assert f"irb2400 at --part-pose {arm['part_pose']}" in line
    assert "0 unreachable, links clear -> scan_rl.mod" in line
    assert f"gave up {given_up} scanning poses" in line
    assert f"{arm['in_spec']:.3f} with it" in line
    # A RAPID module whose targets, read back, are the fitted plan's poses thinned, each its
    # own, where the part stands in the arm's base frame.
    text = (out / "scan_rl.mod").read_text()
    assert text.startswith("MODULE ") and "MoveAbsJ" in text
    poses, scanning = parse_program(text, "rapid")
    T_base_part = np.asarray(arm["T_base_part"])
    kept = plan_motion(fitted, ExportOptions(scan=ScanSpec())).source
    assert len(poses) == len(kept) < len(fitted)
    expected = T_base_part @ fitted.poses[kept]
    assert np.abs(poses[:, :3, 3] - expected[:, :3, 3]).max() / 1000 < 1e-6
    assert np.array_equal(scanning, fitted.scanning[kept])


def test_every_planner_is_judged_on_one_surface(demo):
    # geometric plans with views (the hemisphere surface), fixed and rl with the top view:
    # the comparison judges all three on the widest surface, named with its area.
    out, printed = demo
    metrics = json.loads((out / "metrics.json").read_text())
    surfaces = {json.dumps(metrics[p]["surface"], sort_keys=True) for p in metrics}
    assert len(surfaces) == 1
    surface = metrics["fixed"]["surface"]
    assert surface["name"] == "hemisphere" and surface["area_mm2"] > 0
    # The printed table wraps its first column: read it as words.
    assert "hemisphere surface," in " ".join(re.sub(r"[│┃]", " ", printed).split())


def test_the_second_process_returns_results_in_order_and_raises_as_here():
    # The rl plan's evaluation and fit run there: its answers and its errors must come back
    # as if computed here (a ValueError stays one clear line), and a process that dies is
    # said to have died, not waited for.
    with SecondProcess(int, "0") as second:
        second.submit(divmod, 7, 2)
        second.submit(math.sqrt, -1.0)
        second.submit(divmod, 9, 4)
        assert second.result() == (3, 1)
        with pytest.raises(ValueError, match="math domain error"):
            second.result()
        assert second.result() == (2, 1)
        second.submit(os._exit, 3)
        with pytest.raises(RuntimeError, match="ended unexpectedly .exit code 3"):
            second.result()


def test_a_failing_setup_of_the_second_process_fails_its_calls():
    with SecondProcess(int, "not a number") as second:
        second.submit(divmod, 7, 2)
        with pytest.raises(ValueError, match="invalid literal for int"):
            second.result()


def test_a_wrong_guess_of_the_rl_plans_surface_is_fitted_again(demo, tmp_path, monkeypatch):
    # The rl plan is fitted before the others are planned, on the surface their default
    # views should make the comparison's; if that guess is wrong the fit is made again, and
    # the demo writes what it writes when the guess is right.
    guess = scanplan.jobs.demo._judged_guess

    def wrong(rl, spec):
        right = guess(rl, spec)
        return replace(right, views="top" if right.views == "auto" else "auto")

    monkeypatch.setattr(scanplan.jobs.demo, "_judged_guess", wrong)
    out = tmp_path / "demo"
    result = CliRunner().invoke(
        app,
        ["demo", "--part", "training-piece", "--points", "96", "-o", str(out)],
        terminal_width=200,
    )
    assert result.exit_code == 0, result.output
    first, _ = demo
    assert (out / "scan_rl.mod").read_text() == (first / "scan_rl.mod").read_text()
    fitted = [json.loads((d / "trajectory_rl_irb2400.json").read_text()) for d in (first, out)]
    for plan in fitted:
        del plan["plan_time_s"]  # the rl planner's wall time, that run's
    assert fitted[0] == fitted[1]


def test_the_report_names_the_program_its_arm_and_what_the_arm_cost(demo):
    out, _ = demo
    page = (out / "report.html").read_text()
    arm = read_json(out / "trajectory_rl_irb2400.json").meta["robot"]
    assert "Program scan_rl.mod (RAPID, ABB)" in page
    assert f"the part at {arm['part_pose']} in the arm" in page
    free, flown = arm["in_spec_without_robot"], arm["in_spec"]
    assert f"in-spec coverage {free:.1%} without it, {flown:.1%} with it" in page
    # Plain words in the prose: no internal key, no backticks; the RL terms folded away.
    prose = re.sub(r"<script.*?</script>", "", page, flags=re.S)
    assert "in_spec_radius_mm" not in prose and "`" not in prose
    details = prose.index("<details>")
    assert prose.index("<th>mean reward</th>") > details
    assert prose.index("<th>in-spec coverage") < details
