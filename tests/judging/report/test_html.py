"""The HTML report: self-contained, one figure per planner, table equal to the metrics."""

from __future__ import annotations

import base64
import csv
import json
import re

import numpy as np
import pytest
import trimesh

from scanplan.core.sensor_spec import SensorSpec
from scanplan.core.trajectory import Trajectory
from scanplan.judging.report.figures import PlannerResult
from scanplan.judging.report.html import metrics_table_html, write_html_report
from scanplan.planning.swaths import Swath
from scanplan.sensor.cloud import simulate_cloud
from scanplan.world.part import part_from_mesh


@pytest.fixture(scope="module")
def results():
    plate = trimesh.creation.box((400, 400, 10))
    plate.apply_translation((0, 0, -5))
    part = part_from_mesh(plate, "plate")
    spec = SensorSpec().with_points(64)
    sw = Swath(0, np.array([-100.0, 0, 400]), np.array([100.0, 0, 400]), np.eye(3)[0], np.eye(3)[1])
    out = []
    for name, h in (("high", 30.0), ("right", 0.0)):
        s = np.linspace(0, 200, 41)
        traj = Trajectory(sw.poses(s, np.full(41, h), np.zeros(41)), np.zeros(41), np.ones(41))
        cloud = simulate_cloud(part, spec, traj)
        metrics = {
            "profiles": 41,
            "distance_error_mm": {"mean_abs": float(np.abs(cloud.distance_error_mm).mean())},
            "coverage_definition": "test definition",
        }
        out.append(PlannerResult(name, traj, cloud, metrics))
    return part, out


def test_report_is_self_contained_and_shows_every_planner(tmp_path, results):
    part, res = results
    log = tmp_path / "train.csv"
    with open(log, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["timesteps", "ep_rew_mean", "r_d"])
        writer.writerows([[i * 2048, -100 + i, -0.5 + 0.01 * i] for i in range(5)])
    out = tmp_path / "report.html"
    write_html_report(out, part, res, "at-c5-4090cs30-495", training_log=log)
    page = out.read_text()
    assert page.startswith("<!DOCTYPE html>")
    assert "<script src=" not in page  # plotly.js is inlined, nothing is fetched
    assert page.count("data-figure=") == 3  # two planners + the training curves
    assert "id='scanplan-plotly-gz'" in page  # plotly.js packed, unpacked by the page
    for name in ("high", "right", "ep_rew_mean", "test definition"):
        assert name in page
    # The table shows each planner's number, rounded as the CLI JSON would be read.
    for r in res:
        assert f"{r.metrics['distance_error_mm']['mean_abs']:.3f}" in page


def test_metrics_table_marks_missing_values(results):
    _, res = results
    table = metrics_table_html(res)
    assert re.search(r"<th>profiles</th><td>41</td><td>41</td>", table)
    assert "RMS" not in table  # rows no planner has are left out


def test_report_needs_a_result(tmp_path, results):
    part, _ = results
    with pytest.raises(ValueError, match="at least one"):
        write_html_report(tmp_path / "r.html", part, [], "s")
    assert not (tmp_path / "r.html").exists()


def test_views_get_their_own_colours_and_the_surface_its_in_spec_map(tmp_path, results):
    from dataclasses import replace

    from scanplan.judging import CoverageMap, SurfaceState
    from scanplan.judging.report.scene import VIEW_COLOURS

    part, res = results
    traj = res[1].trajectory
    # Two views: the second half of the poses as a second block of swaths.
    half = len(traj) // 2
    swath = np.where(np.arange(len(traj)) < half, 0, 1)
    views = [
        {"index": 0, "axis": [0.0, 0.0, 1.0], "first_swath": 0, "last_swath": 0, "passes": 1},
        {"index": 1, "axis": [0.98, 0.0, 0.17], "first_swath": 1, "last_swath": 1, "passes": 1},
    ]
    two = replace(traj, swath=swath, meta={"views": views})
    states = np.array([SurfaceState.IN_SPEC, SurfaceState.OUT_OF_SPEC, SurfaceState.UNSEEN])
    coverage = CoverageMap(np.array([[0.0, 0, 0], [10, 0, 0], [20, 0, 0]]), states.astype(np.int8))
    result = PlannerResult("views", two, res[1].cloud, res[1].metrics, coverage)
    out = tmp_path / "report.html"
    write_html_report(out, part, [result], "at-c5-4090cs30-495")
    page = out.read_text()
    # Named by where they look from (plotly may write ° as \u00b0).
    assert "from above" in page and "from +X, 10\\u00b0 up" in page.replace("°", "\\u00b0")
    assert VIEW_COLOURS[0] in page and VIEW_COLOURS[1] in page
    assert "in-spec map" in page
    for colour in ("#1b9e77", "#d95f02", "#b4b4b4"):  # in spec, out of spec, not seen
        assert colour in page


def test_a_plan_made_for_an_arm_shows_the_arm_and_the_table(tmp_path, results):
    from dataclasses import replace

    from scanplan.judging.report.scene_arm import check_arm
    from scanplan.robot.export import parse_pose_arg
    from scanplan.world.cell import Cell

    part, res = results
    traj = res[1].trajectory
    cell = Cell.around(part)
    arm = check_arm(traj, "ur5e", parse_pose_arg("400,0,-300,0,0,0"), np.eye(4), part, cell)
    out = tmp_path / "report.html"
    write_html_report(out, part, [replace(res[1], cell=cell, arm=arm)], "s")
    page = out.read_text()
    assert '"name":"table"' in page and "ur5e base" in page
    assert "ur5e at pose 0 (view 0, pass 0, first)" in page
    assert '"sliders"' in page  # one arm pose at a time, or all of them


def _figure_traces(page: str, div_id: str) -> dict[str, dict]:
    """The traces of one figure on the page, by name."""
    start = page.index(f"data-figure='{div_id}'>") + len(f"data-figure='{div_id}'>")
    figure = json.loads(page[start : page.index("</script>", start)])
    return {t.get("name", "shared"): t for t in figure["data"]}


def test_the_page_is_compact_unless_asked_for_every_point(tmp_path, results, monkeypatch):
    import scanplan.judging.report.figures as report_figures

    part, res = results
    monkeypatch.setattr(report_figures, "MAX_POINTS_PER_PLANNER", 500)
    total = len(res[0].cloud.points_part)
    assert total > 500
    for full, expected in ((False, 500), (True, total)):
        out = tmp_path / f"report_{full}.html"
        write_html_report(out, part, res[:1], "s", full_3d=full)
        page = out.read_text()
        x = _figure_traces(page, "planner-0")["scan points"]["x"]
        # Coordinates as float32 typed arrays, not decimal lists.
        assert x["dtype"] == "f4" and len(base64.b64decode(x["bdata"])) == 4 * expected
        # plotly.js gzipped (the page unpacks it) unless the page is asked to be full.
        assert ("id='scanplan-plotly-gz'" in page) is not full
        # The part's mesh is sent once and put back into each figure by the page.
        assert _figure_traces(page, "planner-0")["shared"] == {"shared": 0}
        assert '"name":"part"' in page
