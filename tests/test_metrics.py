"""Scan-quality metrics (SPEC §7), maps and the plan/evaluate command line (SPEC §8)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

from scanplan.cli import app
from scanplan.metrics import evaluate
from scanplan.part import part_from_mesh
from scanplan.quantities import ScanSpec
from scanplan.report.maps import metrics_table_markdown, plot_comparison, plot_error_maps
from scanplan.sensor import SensorSpec
from scanplan.swaths import Swath
from scanplan.trajectory import Trajectory

SENSOR = SensorSpec()
SPEC = ScanSpec(SENSOR)
X, Y = np.eye(3)[0], np.eye(3)[1]


@pytest.fixture(scope="module")
def plate():
    mesh = trimesh.creation.box((600.0, 300.0, 10.0))
    mesh.apply_translation((0, 0, -5.0))  # top face at z = 0
    return part_from_mesh(mesh, "plate")


def straight(s_mm, h_mm=0.0, pitch=0.0, swath_index=0):
    sw = Swath(0, np.array([-320.0, 0, 400.0]), np.array([320.0, 0, 400.0]), X, Y)
    s = np.asarray(s_mm, dtype=float)
    poses = sw.poses(s, np.full_like(s, h_mm), np.full_like(s, pitch))
    return Trajectory(poses, np.full(len(s), swath_index), np.ones(len(s), bool), planner="t")


def test_plate_at_working_distance_is_exact(plate):
    traj = straight(np.arange(20.25, 620.0, 0.5))  # the sensor stays over the plate
    m = evaluate(plate, SPEC, traj, points_per_profile=512)
    assert m.distance_error_mean_abs_mm < 0.02 and m.distance_error_p95_abs_mm < 0.04
    assert m.orientation_error_mean_deg < 1e-3
    assert m.in_range_fraction == 1.0
    # Columns are evenly spaced across the 495 mm line: 300 mm of plate under it.
    on_plate = 300.0 / SENSOR.line_width_mm
    assert m.valid_fraction == pytest.approx(on_plate, abs=0.01)
    assert m.spacing_mean_mm == pytest.approx(0.5, abs=1e-3) and m.spacing_cv < 0.01
    assert m.backward_steps == 0 and m.coverage_fraction > 0.99
    assert m.reward_mean > -1e-3  # on every term's optimum
    # Off the plate a profile has no valid point: each such step is charged -1 on R_D.
    off = evaluate(plate, SPEC, straight(np.arange(0, 640.0, 0.5)), points_per_profile=128)
    assert off.r_d_mean == pytest.approx(-80 / 1279, abs=2e-3)
    assert m.cycle_time_s == pytest.approx(len(traj) / 200.0)


def test_height_error_and_tilt_are_measured(plate):
    m = evaluate(
        plate, SPEC, straight(np.arange(100, 300.0, 0.5), h_mm=30.0), points_per_profile=256
    )
    assert m.distance_error_mean_mm == pytest.approx(30.0, abs=0.05)
    assert m.distance_error_rms_mm == pytest.approx(30.0, abs=0.05)
    tilt = math.radians(10)
    m = evaluate(
        plate, SPEC, straight(np.arange(100, 300.0, 0.5), pitch=tilt), points_per_profile=256
    )
    assert m.orientation_error_mean_deg == pytest.approx(10.0, abs=0.01)
    assert m.r_alpha_mean == pytest.approx(-((10 / 30) ** 2), abs=1e-3)


def test_spacing_gap_and_backward_steps(plate):
    s = np.concatenate([np.arange(0, 50, 0.5), [52.0, 51.5], np.arange(52.5, 80, 0.5)])
    m = evaluate(plate, SPEC, straight(s + 100.0), points_per_profile=256)
    assert m.backward_steps == 1
    assert m.spacing_max_gap_mm == pytest.approx(2.5, abs=0.01)


def test_half_the_plate_is_half_covered(plate):
    # One pass over x in [-320, 0] sees the half x < 0 of the top face.
    m = evaluate(plate, SPEC, straight(np.arange(0, 320.0, 0.5)), points_per_profile=512)
    assert m.coverage_fraction == pytest.approx(0.5, abs=0.02)
    assert m.visible_area_mm2 == pytest.approx(600 * 300, rel=0.01)


def test_coverage_ignores_what_a_top_down_raster_cannot_see():
    # A block on a plate: its walls (vertical) and the plate under it are not counted.
    base = trimesh.creation.box((600.0, 300.0, 10.0))
    block = trimesh.creation.box((100.0, 100.0, 80.0))
    block.apply_translation((0, 0, 45.0))
    part = part_from_mesh(trimesh.util.concatenate([base, block]), "block")
    m = evaluate(part, SPEC, straight(np.arange(0, 640.0, 0.5), h_mm=5.0), points_per_profile=512)
    assert m.visible_area_mm2 == pytest.approx(600 * 300, rel=0.02)


def test_full_and_subsampled_fans_agree(plate):
    traj = straight(np.arange(200, 260.0, 0.5), h_mm=10.0)
    full = evaluate(plate, SPEC, traj)
    sub = evaluate(plate, SPEC, traj, points_per_profile=256)
    assert full.points_per_profile == 4096
    assert sub.distance_error_mean_abs_mm == pytest.approx(
        full.distance_error_mean_abs_mm, abs=0.02
    )


def test_json_has_the_spec_keys_and_no_nan(plate):
    data = evaluate(plate, SPEC, straight([300.0]), points_per_profile=64).to_json_dict()
    for key in (
        "profiles",
        "in_range_fraction",
        "coverage_fraction",
        "path_length_mm",
        "plan_time_s",
    ):
        assert key in data
    assert set(data["distance_error_mm"]) >= {"mean_abs", "rms", "p95_abs"}
    assert set(data["orientation_error_deg"]) >= {"mean", "p95"}
    assert set(data["spacing_mm"]) >= {"mean", "cv", "max_gap", "backward_steps"}
    assert "top-down" in data["coverage_definition"]
    text = json.dumps(data, allow_nan=False)  # raises on NaN/inf
    assert "NaN" not in text


def test_out_of_reach_raises(plate):
    with pytest.raises(ValueError, match="outside the sensor's reach"):
        evaluate(plate, SPEC, straight(np.arange(0, 20.0, 0.5), h_mm=500.0), points_per_profile=64)


def test_maps_and_table(plate, tmp_path):
    a = evaluate(plate, SPEC, straight(np.arange(0, 640.0, 1.0), h_mm=5.0), points_per_profile=256)
    b = evaluate(plate, SPEC, straight(np.arange(0, 640.0, 1.0)), points_per_profile=256)
    files = plot_error_maps(a, tmp_path / "maps")
    assert sorted(f.name for f in files) == ["distance_error.png", "orientation_error.png"]
    assert all(f.stat().st_size > 10_000 for f in files)
    cmp = plot_comparison([("high", a), ("exact", b)], "distance", tmp_path / "cmp.png", "plate")
    assert cmp.is_file()
    table = metrics_table_markdown([a, b], ["high", "exact"])
    assert "| mean |distance error| (mm) | 5.00" in table.replace("5.000", "5.00")
    assert len(table.splitlines()) > 10


# ---- command line -------------------------------------------------------------------------
runner = CliRunner()


@pytest.fixture()
def plate_file(tmp_path):
    mesh = trimesh.creation.box((400.0, 200.0, 10.0))
    path = tmp_path / "plate.stl"
    mesh.export(path)
    return path


def test_cli_plan_then_evaluate_json(plate_file, tmp_path):
    traj = tmp_path / "t.csv"
    result = runner.invoke(app, ["plan", str(plate_file), "--planner", "fixed", "-o", str(traj)])
    assert result.exit_code == 0, result.output
    assert traj.read_text().startswith("swath,scanning,x_mm")
    result = runner.invoke(
        app, ["evaluate", str(plate_file), str(traj), "--json", "--points", "128"]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)  # exactly one JSON object
    assert data["profiles"] > 700 and data["coverage_fraction"] > 0.99
    report = tmp_path / "report"
    result = runner.invoke(
        app, ["evaluate", str(plate_file), str(traj), "--points", "128", "-o", str(report)]
    )
    assert result.exit_code == 0, result.output
    names = {p.name for p in report.iterdir()}
    assert {"distance_error.png", "orientation_error.png", "metrics.md", "metrics.json"} <= names
    assert "report.html" in names


def test_cli_bad_trajectory_and_out_of_reach(plate_file, tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("swath,scanning,x_mm\n1,2\n")
    out = tmp_path / "rep"
    result = runner.invoke(app, ["evaluate", str(plate_file), str(bad), "-o", str(out)])
    assert result.exit_code == 2
    assert result.output.strip().count("\n") == 0 and "bad.csv" in result.output
    assert not out.exists()

    far = tmp_path / "far.csv"
    high = straight(np.arange(0, 20.0, 0.5), h_mm=800.0)
    from scanplan.trajectory import write_csv

    write_csv(high, far)
    result = runner.invoke(app, ["evaluate", str(plate_file), str(far), "--json", "-o", str(out)])
    assert result.exit_code == 2
    assert "outside the sensor's reach" in result.output and not out.exists()

    result = runner.invoke(
        app, ["plan", str(plate_file), "--planner", "nope", "-o", str(tmp_path / "x.csv")]
    )
    assert result.exit_code == 2 and not (tmp_path / "x.csv").exists()
