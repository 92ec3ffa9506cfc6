"""The command line: part, scan and export, and its one-line errors."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

from scanplan.cli import app
from scanplan.swaths import Swath
from scanplan.trajectory import Trajectory, write_csv

runner = CliRunner()


def run(*args: str):
    return runner.invoke(app, list(args))


@pytest.fixture()
def plate_and_trajectory(tmp_path):
    plate = trimesh.creation.box((600, 600, 10))
    plate.apply_translation((0, 0, -5))
    plate_path = tmp_path / "plate.stl"
    plate.export(plate_path)
    sw = Swath(0, np.array([-50.0, 0, 400]), np.array([50.0, 0, 400]), np.eye(3)[0], np.eye(3)[1])
    poses = sw.poses(np.linspace(0, 100, 21), np.zeros(21), np.zeros(21))
    traj_path = tmp_path / "t.csv"
    write_csv(Trajectory(poses, np.zeros(21, int), np.ones(21, bool)), traj_path)
    return plate_path, traj_path


def test_part_writes_a_builtin_mesh(tmp_path):
    out = tmp_path / "tp.stl"
    result = run("part", "training-piece", "-o", str(out))
    assert result.exit_code == 0, result.output
    mesh = trimesh.load(out)
    assert mesh.extents == pytest.approx([1050, 150, 50], rel=0.02)


def test_part_unknown_name_is_one_line(tmp_path):
    out = tmp_path / "x.stl"
    result = run("part", "teapot", "-o", str(out))
    assert result.exit_code == 2
    assert result.output.strip().count("\n") == 0
    assert "unknown part 'teapot'" in result.output
    assert not out.exists()


def test_scan_writes_a_point_cloud_with_error_fields(plate_and_trajectory, tmp_path):
    plate, traj = plate_and_trajectory
    out = tmp_path / "cloud.ply"
    result = run("scan", str(plate), str(traj), "-o", str(out), "--no-noise")
    assert result.exit_code == 0, result.output
    cloud = trimesh.load(out)
    assert len(cloud.vertices) == 21 * 4096
    raw = cloud.metadata["_ply_raw"]["vertex"]["data"]
    assert np.allclose(raw["distance_error_mm"], 0.0, atol=0.004)
    assert np.allclose(raw["orientation_error_deg"], 0.0, atol=1e-3)
    assert {"red", "green", "blue", "profile", "swath"} <= set(raw.dtype.names)


def test_scan_out_of_reach_and_bad_trajectory(plate_and_trajectory, tmp_path):
    plate, traj = plate_and_trajectory
    far = tmp_path / "far.csv"
    text = traj.read_text().replace(",400.000000,", ",900.000000,")
    far.write_text(text)
    out = tmp_path / "cloud.ply"
    result = run("scan", str(plate), str(far), "-o", str(out))
    assert result.exit_code == 2
    assert "outside the sensor's reach" in result.output
    assert not out.exists()
    bad = tmp_path / "bad.csv"
    bad.write_text("swath,scanning\n1,2\n")
    result = run("scan", str(plate), str(bad), "-o", str(out))
    assert result.exit_code == 2
    assert "bad.csv line 1" in result.output
    assert "Traceback" not in result.output
    assert not out.exists()
    result = run("scan", str(tmp_path / "nope.stl"), str(traj), "-o", str(out))
    assert result.exit_code == 2 and "does not exist" in result.output


@pytest.mark.parametrize("fmt", ["urscript", "rapid", "krl", "ros", "csv"])
def test_export_every_format(plate_and_trajectory, tmp_path, fmt):
    from scanplan.export import parse_program
    from scanplan.trajectory import read_csv

    _, traj_path = plate_and_trajectory
    out = tmp_path / f"prog.{fmt}"
    result = run(
        "export", str(traj_path), "--format", fmt, "--part-pose", "500,0,-200,0,0,0", "-o", str(out)
    )
    assert result.exit_code == 0, result.output
    poses, scanning = parse_program(out.read_text(), fmt)
    expected = read_csv(traj_path).poses.copy()
    expected[:, :3, 3] += (500, 0, -200)
    assert np.allclose(poses[:, :3, 3], expected[:, :3, 3], atol=1e-3)
    assert scanning.all()


def test_export_bad_pose_leaves_no_file(plate_and_trajectory, tmp_path):
    _, traj_path = plate_and_trajectory
    out = tmp_path / "prog.script"
    result = run("export", str(traj_path), "--tcp", "1,2,three", "-o", str(out))
    assert result.exit_code == 2
    assert "error:" in result.output
    assert not out.exists()
