"""A plan file carries what it was planned under, and is judged by it: the same plan from its
CSV and its JSON scores the same; an option that differs from the plan is said in one line."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from typer.testing import CliRunner

from scanplan.cli import app
from scanplan.core.context import PlanContext, judged_alike, recorded
from scanplan.core.plan_file import read_trajectory, write_csv, write_json
from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.judging import evaluate

runner = CliRunner()
SPEC = ScanSpec()


def test_the_context_survives_its_json_record():
    context = PlanContext(
        replace(SPEC, tol_distance_mm=5.0, tol_angle_rad=math.radians(10.0)),
        planner="geometric",
        views="auto",
        roi="+z:30",
        full_beam_angle=True,
    )
    back = PlanContext.from_json_dict(json.loads(json.dumps(context.to_json_dict())), "here")
    assert back.spec.sensor == context.spec.sensor
    assert back.spec.tolerance_mm == 5.0
    assert back.spec.tol_angle_rad == pytest.approx(math.radians(10.0))
    assert (back.views, back.roi, back.surface, back.full_beam_angle) == (
        "auto",
        "+z:30",
        "roi",
        True,
    )
    assert back.limits == context.limits
    broken = context.to_json_dict() | {"scan_spec": {"delta_s_opt_mm": -1}}
    with pytest.raises(ValueError, match="here: context.scan_spec"):
        PlanContext.from_json_dict(broken, "here")


@pytest.fixture(scope="module")
def housing_plan(housing_views):
    plans, traj = housing_views
    assert len(plans) > 1  # the point: a plan of several views
    return traj


def test_csv_and_json_of_one_multi_view_plan_give_the_same_figures(housing, housing_plan, tmp_path):
    write_csv(housing_plan, tmp_path / "plan.csv")
    write_json(housing_plan, tmp_path / "plan.json")
    from_csv = read_trajectory(tmp_path / "plan.csv")
    from_json = read_trajectory(tmp_path / "plan.json")
    assert from_csv.meta["context"] == from_json.meta["context"] == housing_plan.meta["context"]
    assert from_csv.meta["views"] == from_json.meta["views"]
    assert recorded(from_csv, ScanSpec()).surface == "hemisphere"
    a = evaluate(housing, SPEC, from_csv, points_per_profile=128)
    b = evaluate(housing, SPEC, from_json, points_per_profile=128)
    assert a.surface == b.surface == "hemisphere"
    assert a.visible_area_mm2 == b.visible_area_mm2
    assert a.in_spec_coverage == pytest.approx(b.in_spec_coverage, abs=1e-3)
    # Common CSV tools read the file, taking the context lines for comments.
    table = np.genfromtxt(tmp_path / "plan.csv", delimiter=",", names=True, comments="#")
    assert len(table) == len(housing_plan)
    assert np.allclose(table["x_mm"], housing_plan.positions_mm[:, 0], atol=1e-5)


def test_a_broken_context_line_is_one_clear_error(tmp_path):
    path = tmp_path / "plan.csv"
    path.write_text("swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz\n# context: {not json\n")
    with pytest.raises(ValueError, match="line 2: the context record is not valid JSON"):
        read_trajectory(path)


def test_comparisons_judge_every_plan_on_the_widest_surface():
    top = PlanContext(SPEC, planner="fixed", views="top")
    auto = PlanContext(SPEC, planner="geometric", views="auto", full_beam_angle=True)
    judged = judged_alike([top, auto])
    assert [c.surface for c in judged] == ["hemisphere", "hemisphere"]
    assert [c.full_beam_angle for c in judged] == [False, True]  # each keeps its reward


def test_the_reward_is_the_one_of_the_env_the_plan_came_from(tilted_strip, straight_pass):
    # A 20° slope across the pass: the pitch error (v0) is 0, the beam angle (v1) is 20°.
    v0 = evaluate(tilted_strip, SPEC, straight_pass, points_per_profile=256)
    v1 = evaluate(
        tilted_strip,
        SPEC,
        straight_pass,
        points_per_profile=256,
        context=PlanContext(SPEC, full_beam_angle=True),
    )
    assert v0.r_alpha_mean > -1e-3
    assert v1.r_alpha_mean == pytest.approx(-((20.0 / 30.0) ** 2), abs=0.01)
    assert v1.in_spec_coverage == v0.in_spec_coverage  # the reward alone differs


def test_with_a_region_of_interest_every_statistic_is_the_regions(step_block):
    # A pass along x over y = 0 at W_d above the plate: its line spans the plate and the
    # block 60 mm higher beside it; the region of interest is the plate.
    s = np.arange(-20.0, 620.0, 0.5)
    poses = np.repeat(np.eye(4)[None], len(s), axis=0)
    poses[:, :3, :3] = [[0, 1, 0], [1, 0, 0], [0, 0, -1]]  # x_s = y, y_s = x, z_s down
    poses[:, :3, 3] = np.stack([s - 300.0, 0 * s, 0 * s + 400.0], axis=1)
    traj = Trajectory(poses, np.zeros(len(s), int), np.ones(len(s), bool), planner="straight")
    roi = PlanContext(SPEC, roi="box:-300,-200,-1,300,90,1")
    on_roi = evaluate(step_block, SPEC, traj, points_per_profile=256, context=roi)
    whole = evaluate(step_block, SPEC, traj, points_per_profile=256, context=PlanContext(SPEC))
    assert on_roi.surface == "roi" and whole.surface == "top"
    assert on_roi.visible_area_mm2 < whole.visible_area_mm2
    assert on_roi.in_spec_coverage >= 0.95
    assert on_roi.distance_error_mean_abs_mm < 0.1 <= SPEC.tolerance_mm
    assert on_roi.in_range_fraction == 1.0
    # Over the whole line, the block top (60 mm off W_d) is a quarter of the points.
    assert whole.distance_error_mean_abs_mm == pytest.approx(15.0, abs=3.0)


def test_evaluate_takes_the_plan_context_and_names_what_an_option_changes(plate_file, tmp_path):
    plan = tmp_path / "plan.csv"
    result = runner.invoke(
        app, ["plan", str(plate_file), "--planner", "fixed", "--tolerance", "5,10", "-o", str(plan)]
    )
    assert result.exit_code == 0, result.output
    as_planned = runner.invoke(
        app, ["evaluate", str(plate_file), str(plan), "--json", "--points", "128"]
    )
    assert as_planned.exit_code == 0, as_planned.output
    data = json.loads(as_planned.stdout)
    assert data["tolerance"] == {"mm": 5.0, "deg": pytest.approx(10.0)}
    assert data["surface"]["name"] == "top" and data["surface"]["area_mm2"] > 0
    assert as_planned.stderr == ""
    changed = runner.invoke(
        app,
        [
            "evaluate",
            str(plate_file),
            str(plan),
            "--json",
            "--points",
            "128",
            "--tolerance",
            "6,10",
        ],
    )
    assert changed.exit_code == 0
    assert json.loads(changed.stdout)["tolerance"]["mm"] == 6.0
    note = changed.stderr.strip().splitlines()
    assert len(note) == 1 and "tolerance 6 mm" in note[0] and "planned: 5 mm" in note[0]
