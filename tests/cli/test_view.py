"""`scanplan view`: the plan's 3-D page without simulating the scan — part, passes and the
arm drawn reaching them from its base; unreachable poses marked; bad input in one line."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest

from helpers import plate_file, run_cli, straight
from scanplan.core.context import PlanContext
from scanplan.core.plan_file import write_csv
from scanplan.core.quantities import ScanSpec
from scanplan.judging.report.scene import PROBLEM_COLOUR
from scanplan.judging.report.scene_arm import check_arm
from scanplan.robot.export import parse_pose_arg

PART_POSE = "400,0,-300,0,0,0"  # a pass 400 mm above the plate, in reach of a UR5e


def robot_plan(tmp_path, part_pose=PART_POSE, part=True):
    """A 41-pose pass over the plate recorded as made for a UR5e at `part_pose`."""
    traj = straight(np.linspace(220.0, 420.0, 41))  # x from -100 to 100 mm, W_d above
    context = PlanContext(ScanSpec(), part=plate_file(tmp_path) if part else "")
    robot = {
        "robot": "ur5e",
        "part_pose": part_pose,
        "tcp": "0,0,0,0,0,0",
        "T_base_part": parse_pose_arg(part_pose).tolist(),
        "T_flange_sensor": np.eye(4).tolist(),
    }
    path = tmp_path / "plan.csv"
    meta = {"context": context.to_json_dict(), "robot": robot}
    write_csv(replace(traj, planner="t", meta=meta), path)
    return path


@pytest.fixture()
def no_simulation(monkeypatch):
    """The page is drawn from the plan alone: any simulation is a failure."""

    def refuse(*args, **kwargs):
        raise AssertionError("view simulated the scan")

    monkeypatch.setattr("scanplan.sensor.profilometer.LineProfilometer.measure_many", refuse)
    monkeypatch.setattr("scanplan.judging.evaluation.evaluate", refuse)


def test_view_draws_part_passes_and_arm_without_simulating(tmp_path, no_simulation):
    plan = robot_plan(tmp_path)
    page = tmp_path / "page.html"
    result = run_cli("view", str(plan), "-o", str(page))
    assert result.exit_code == 0, result.output
    assert re.fullmatch(
        rf"view: 1 view, 1 pass, 41 profiles, 41 poses, arm ur5e at {PART_POSE} "
        r"\(0 unreachable, 0 link "
        rf"collisions\) -> {re.escape(str(page))} \(\d+\.\d MB\)\n",
        result.output,
    )
    html = page.read_text()
    assert "<script src=" not in html  # plotly.js inlined, as the report does
    for name in ('"name":"part"', '"name":"table"', '"name":"passes"', "ur5e at pose 0 ",
                 "ur5e base"):  # fmt: skip
        assert name in html
    assert page.stat().st_size < 8e6


def test_the_arm_reaches_each_drawn_pose_from_its_base(tmp_path):
    from scanplan.core.context import recorded
    from scanplan.core.plan_file import read_trajectory
    from scanplan.world.cell import planned_cell
    from scanplan.world.part import load_part

    traj = read_trajectory(robot_plan(tmp_path))
    part = load_part(recorded(traj, ScanSpec()).part)
    T_base_part = parse_pose_arg(PART_POSE)
    arm = check_arm(
        traj, "ur5e", T_base_part, np.eye(4), part, planned_cell(recorded(traj, ScanSpec()), part)
    )
    assert list(arm.shown) == [0, 20, 40]  # one pass: its first, middle and last pose
    # The chain stands on the base, its wrist ends at the flange, which (TCP identity) is the
    # sensor's pose; no link sticks out beyond the UR5e's reach.
    assert np.allclose(arm.base_part, [-400.0, 0.0, 300.0])
    assert np.allclose(arm.capsules_part[:, 0, 0, :2], arm.base_part[:2], atol=1e-6)
    assert np.allclose(arm.capsules_part[:, -2, 1], traj.positions_mm[arm.shown], atol=1e-6)
    assert np.allclose(arm.capsules_part[:, -1, 1], traj.positions_mm[arm.shown], atol=1e-6)
    assert np.linalg.norm(arm.capsules_part - arm.base_part, axis=-1).max() < 1000.0


def test_an_unreachable_plan_marks_its_poses(tmp_path, no_simulation):
    plan = robot_plan(tmp_path, part_pose="3000,0,0,0,0,0")  # far beyond a UR5e's reach
    page = tmp_path / "page.html"
    result = run_cli("view", str(plan), "-o", str(page))
    assert result.exit_code == 0, result.output
    assert "(41 unreachable, 0 link collisions)" in result.output
    html = page.read_text()
    assert "41 poses: unreachable or beyond joint limits" in html
    assert PROBLEM_COLOUR in html


def test_view_with_robot_options_and_without_an_arm(tmp_path):
    plan = robot_plan(tmp_path)
    page = tmp_path / "page.html"
    result = run_cli("view", str(plan), "-o", str(page), "--robot", "none")
    assert result.exit_code == 0, result.output
    assert ", no arm -> " in result.output and "ur5e base" not in page.read_text()
    result = run_cli(
        "view", str(plan), "-o", str(page), "--robot", "ur10e", "--part-pose", "500,0,-300,0,0,0"
    )
    assert result.exit_code == 0, result.output
    assert "arm ur10e at 500,0,-300,0,0,0 (0 unreachable" in result.output


@pytest.mark.parametrize("case", ["missing plan", "no part", "bad robot", "bad part"])
def test_bad_input_is_one_line_and_no_page(tmp_path, case):
    plan = robot_plan(tmp_path, part=case != "no part")
    args = {
        "missing plan": [str(tmp_path / "nothing.csv")],
        "no part": [str(plan)],
        "bad robot": [str(plan), "--robot", "ur99"],
        "bad part": [str(plan), "--part", str(tmp_path / "gone.stl")],
    }[case]
    page = tmp_path / "page.html"
    result = run_cli("view", *args, "-o", str(page))
    assert result.exit_code == 2, result.output
    assert result.output.startswith("error: ") and result.output.count("\n") == 1
    if case == "no part":
        assert "--part is required" in result.output
    assert not page.exists()
    assert not list(tmp_path.glob(".page.html*"))  # no temporary file left either


def test_the_report_of_a_plan_made_for_an_arm_draws_it(tmp_path):
    plan = robot_plan(tmp_path)
    result = run_cli("evaluate", plate_file(tmp_path), str(plan), "-o", str(tmp_path / "r"))
    assert result.exit_code == 0, result.output
    html = (tmp_path / "r" / "report.html").read_text()
    assert "ur5e base" in html and '"name":"table"' in html
    # An arm the report can no longer rebuild (its file gone): said, the rest still written.
    text = plan.read_text().replace('"robot": "ur5e"', '"robot": "gone.toml"')
    plan.write_text(text)
    result = run_cli("evaluate", plate_file(tmp_path), str(plan), "-o", str(tmp_path / "r"))
    assert result.exit_code == 0, result.output
    html = (tmp_path / "r" / "report.html").read_text()
    assert "the cell and the arm are not drawn" in html and "ur5e base" not in html


def test_links_in_the_table_are_drawn_red(tmp_path, no_simulation):
    # The base 200 mm under the plate, inside the table's footprint: the column stands in it.
    plan = robot_plan(tmp_path, part_pose="300,0,200,0,0,0")
    page = tmp_path / "page.html"
    result = run_cli("view", str(plan), "-o", str(page))
    assert result.exit_code == 0, result.output
    assert "(0 unreachable, 41 link collisions)" in result.output
    html = page.read_text()
    assert "41 poses: a link collides" in html and "(view 0, pass 0, first): links collide" in html


def test_the_page_renders_in_a_browser_with_the_part_lit(tmp_path):
    """Headless Chromium (software WebGL) draws the page: the shaded part shows in many
    tones of its blue-grey, not a blank scene."""
    import shutil
    import subprocess

    from PIL import Image

    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("no chromium here")
    page, shot = tmp_path / "page.html", tmp_path / "page.png"
    assert run_cli("view", str(robot_plan(tmp_path)), "-o", str(page)).exit_code == 0
    subprocess.run(
        [browser, "--headless", "--no-sandbox", "--use-angle=swiftshader",
         "--enable-unsafe-swiftshader", "--window-size=1400,1000", f"--screenshot={shot}",
         # Without a time budget the shot is taken at the load event, which on a busy
         # machine comes before the software WebGL has drawn the scene.
         "--virtual-time-budget=15000", page.as_uri()],
        capture_output=True, timeout=120, check=True, cwd=tmp_path,
    )  # fmt: skip
    rgb = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    r, b = rgb[..., 0], rgb[..., 2]
    part = (b - r >= 8) & (b - r <= 60) & (r >= 40) & (r <= 200)  # the part's #8c99a6, shaded
    assert part.mean() > 0.01, part.mean()
    assert len(np.unique(rgb[part], axis=0)) > 50  # lit: many tones, not one flat colour
