"""`scanplan plan`, `scan` and `evaluate` on the command line: what they write and print, the
options that reach the library (tolerance, views, region of interest), one-line errors."""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

from helpers import (
    BLOCK_BOX,
    loopback_cluster,
    overhang_part,
    plate_with_block,
    run_cli,
    straight,
)
from scanplan.cli import app
from scanplan.core.plan_file import read_trajectory, write_csv
from scanplan.judging import SurfaceState
from scanplan.judging.report.maps import COVERAGE_COLOURS

runner = CliRunner()


def cycle_line(output: str) -> str:
    """The one line of a command's output that gives the cycle time."""
    (line,) = [ln for ln in output.splitlines() if ln.startswith("cycle time ")]
    return line


def test_scan_writes_a_point_cloud_with_error_fields(plate_and_trajectory, tmp_path):
    plate, traj = plate_and_trajectory
    out = tmp_path / "cloud.ply"
    result = run_cli("scan", str(plate), str(traj), "-o", str(out), "--no-noise")
    assert result.exit_code == 0, result.output
    cloud = trimesh.load(out)
    assert len(cloud.vertices) == 21 * 4096
    raw = cloud.metadata["_ply_raw"]["vertex"]["data"]
    assert np.allclose(raw["distance_error_mm"], 0.0, atol=0.004)
    assert np.allclose(raw["orientation_error_deg"], 0.0, atol=1e-3)
    assert {"red", "green", "blue", "profile", "swath"} <= set(raw.dtype.names)


def test_scan_writes_fewer_points_on_request_and_says_how_many_first(
    plate_and_trajectory, tmp_path
):
    from scanplan.sensor.cloud import ply_size_bytes

    plate, traj = plate_and_trajectory
    out = tmp_path / "cloud.ply"
    result = run_cli("scan", str(plate), str(traj), "-o", str(out), "--max-points", "5000")
    assert result.exit_code == 0, result.output
    full = 21 * 4096
    assert f"21 profiles x 4096 columns: up to {full:,} points" in result.output
    cloud = trimesh.load(out)
    assert len(cloud.vertices) == 5000  # every point valid: exactly the cap
    assert out.stat().st_size == pytest.approx(ply_size_bytes(5000), abs=64)
    profile = cloud.metadata["_ply_raw"]["vertex"]["data"]["profile"]
    assert (np.diff(profile) >= 0).all() and len(np.unique(profile)) == 21  # spread, in order
    assert f"5000 points from 21 profiles -> {out} (0.2 MB)" in result.output
    # Fewer columns: a thinner fan over the same line.
    result = run_cli("scan", str(plate), str(traj), "-o", str(out), "--points", "64")
    assert result.exit_code == 0, result.output
    assert len(trimesh.load(out).vertices) == 21 * 64


def test_scan_out_of_reach_and_bad_trajectory(plate_and_trajectory, tmp_path):
    plate, traj = plate_and_trajectory
    far = tmp_path / "far.csv"
    text = traj.read_text().replace(",400.000000,", ",900.000000,")
    far.write_text(text)
    out = tmp_path / "cloud.ply"
    result = run_cli("scan", str(plate), str(far), "-o", str(out))
    assert result.exit_code == 2
    assert "outside the sensor's reach" in result.output
    assert not out.exists()
    bad = tmp_path / "bad.csv"
    bad.write_text("swath,scanning\n1,2\n")
    result = run_cli("scan", str(plate), str(bad), "-o", str(out))
    assert result.exit_code == 2
    assert "bad.csv line 1" in result.output
    assert "Traceback" not in result.output
    assert not out.exists()
    result = run_cli("scan", str(tmp_path / "nope.stl"), str(traj), "-o", str(out))
    assert result.exit_code == 2 and "does not exist" in result.output


def test_cli_plan_then_evaluate_json(plate_file, tmp_path):
    traj = tmp_path / "t.csv"
    result = runner.invoke(app, ["plan", str(plate_file), "--planner", "fixed", "-o", str(traj)])
    assert result.exit_code == 0, result.output
    assert traj.read_text().startswith("swath,scanning,x_mm")
    planned = cycle_line(result.stdout)
    assert "; trapezoidal, nominal limits)" in planned
    result = runner.invoke(
        app, ["evaluate", str(plate_file), str(traj), "--json", "--points", "128"]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)  # exactly one JSON object
    assert data["profiles"] > 700 and data["coverage_fraction"] > 0.99
    # The plate is all within reach: in-spec coverage is its own share of the ceiling.
    assert data["visibility_ceiling"] == pytest.approx(1.0, abs=1e-3)
    assert data["in_spec_of_ceiling"] == pytest.approx(data["in_spec_coverage"], abs=1e-3)
    # plan and evaluate time the same plan with the same model and limits.
    cycle = data["cycle_time"]
    assert cycle["limits"]["name"] == "nominal" and cycle["total_s"] == data["cycle_time_s"]
    assert f"cycle time {data['cycle_time_s']:.1f} s (scanning " in planned
    assert f"in {cycle['passes']} pass" in planned
    # The dent the plan would find, predicted from the same scan: a fixed pass over a flat
    # plate at W_d finds sub-millimetre dents, and the JSON and the line say the same.
    found = data["detectable"]
    assert found["type"] == "dent" and 0.01 < found["a50_mm"] < found["a90_mm"] < 1.0
    report = tmp_path / "report"
    result = runner.invoke(
        app, ["evaluate", str(plate_file), str(traj), "--points", "128", "-o", str(report)]
    )
    assert result.exit_code == 0, result.output
    assert cycle_line(result.stdout) == planned
    share = f"{data['in_spec_of_ceiling']:.1%} of its visibility ceiling 100.0% | "
    assert share in result.stdout
    assert f"| dent found at 90 %: {found['a90_mm']:.3f} mm deep (predicted) |" in result.stdout
    names = {p.name for p in report.iterdir()}
    assert {"distance_error.png", "orientation_error.png", "metrics.md", "metrics.json"} <= names
    assert (
        "detectability.png" in names and "dent found at 90 %" in (report / "metrics.md").read_text()
    )
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

    write_csv(high, far)
    result = runner.invoke(app, ["evaluate", str(plate_file), str(far), "--json", "-o", str(out)])
    assert result.exit_code == 2
    assert "outside the sensor's reach" in result.output and not out.exists()

    result = runner.invoke(
        app, ["plan", str(plate_file), "--planner", "nope", "-o", str(tmp_path / "x.csv")]
    )
    assert result.exit_code == 2 and not (tmp_path / "x.csv").exists()


@pytest.fixture()
def strip_files(tmp_path, tilted_strip):

    mesh_path = tmp_path / "strip.stl"
    tilted_strip.mesh.export(mesh_path)
    traj_path = tmp_path / "strip.csv"
    write_csv(straight(np.arange(120.0, 520.0, 0.5)), traj_path)
    return mesh_path, traj_path


def test_cli_tolerance_puts_the_tilted_strip_in_spec(strip_files):
    mesh, traj = strip_files
    base = ["evaluate", str(mesh), str(traj), "--points", "256"]
    default = json.loads(runner.invoke(app, [*base, "--json"]).stdout)
    wide = json.loads(runner.invoke(app, [*base, "--json", "--tolerance", "12.5,25"]).stdout)
    assert default["in_spec_coverage"] < 0.01 and wide["in_spec_coverage"] > 0.95
    assert wide["tolerance"] == {"mm": 12.5, "deg": pytest.approx(25.0)}
    printed = runner.invoke(app, [*base, "--tolerance", "12.5,25"]).stdout
    assert printed.startswith("in-spec coverage 9") and "(±12.5 mm, 25°)" in printed


@pytest.mark.parametrize("bad", ["12.5", "a,b", "-1,15", "12.5,0", "12.5,95", "nan,15", "1,2,3"])
def test_cli_bad_tolerance_is_one_line(strip_files, bad):
    mesh, traj = strip_files
    result = runner.invoke(app, ["evaluate", str(mesh), str(traj), "--tolerance", bad])
    assert result.exit_code == 2
    assert result.output.count("\n") == 1 and "--tolerance" in result.output


def test_report_directory_has_the_in_spec_map(plate_file, tmp_path):

    traj = tmp_path / "half.csv"
    write_csv(straight(np.arange(0, 200.0, 0.5)), traj)  # over x < -100 only: part in spec
    out = tmp_path / "rep"
    result = runner.invoke(
        app, ["evaluate", str(plate_file), str(traj), "--points", "256", "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    png = out / "in_spec_coverage.png"
    assert png.stat().st_size > 10_000
    import matplotlib.image

    rgb = (matplotlib.image.imread(png)[..., :3] * 255).astype(int)

    def share(colour: str) -> float:
        target = np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)])
        return float((np.abs(rgb - target).sum(axis=-1) < 30).mean())

    green, grey = (
        share(COVERAGE_COLOURS[s][0]) for s in (SurfaceState.IN_SPEC, SurfaceState.UNSEEN)
    )
    assert green > 0.02 and grey > 0.02
    page = (out / "report.html").read_text()
    assert "In-spec coverage" in page and "in_spec_coverage.png" in page
    assert "in-spec coverage" in (out / "metrics.md").read_text()


def test_failing_report_leaves_no_directory(plate_file, tmp_path, monkeypatch):
    import scanplan.judging.report.html

    traj = tmp_path / "t.csv"

    write_csv(straight(np.arange(200, 260.0, 1.0)), traj)

    def broken(*args, **kwargs):
        raise ValueError("disk full while writing report.html")

    monkeypatch.setattr(scanplan.judging.report.html, "write_html_report", broken)
    out = tmp_path / "reports" / "rep"
    args = ["evaluate", str(plate_file), str(traj), "--points", "64", "-o", str(out)]
    result = runner.invoke(app, args)
    assert result.exit_code == 2 and "disk full" in result.output
    assert not out.exists() and list(out.parent.iterdir()) == []  # no temporary left either
    # An earlier report in its place survives a failing run, and is replaced by a good one.
    out.mkdir()
    (out / "metrics.json").write_text("{}")
    assert runner.invoke(app, args).exit_code == 2
    assert (out / "metrics.json").read_text() == "{}"
    monkeypatch.undo()
    assert runner.invoke(app, args).exit_code == 0
    assert json.loads((out / "metrics.json").read_text())["profiles"] == 60
    assert sorted(p.name for p in out.parent.iterdir()) == ["rep"]


def test_bad_views_options_are_one_line(tmp_path):
    out = tmp_path / "t.csv"
    for extra in (["--views", "side"], ["--views", "auto", "--coverage-target", "0"]):
        result = CliRunner().invoke(app, ["plan", "drone", "-o", str(out), *extra])
        assert result.exit_code == 2 and len(result.stderr.strip().splitlines()) == 1
        assert "--views" in result.stderr or "--coverage-target" in result.stderr
        assert not out.exists()


def test_cli_bad_roi_is_one_line_and_no_output(tmp_path):
    out = tmp_path / "t.csv"
    for roi, message in [("+z:abc", "--roi"), ("box:5000,5000,0,6000,6000,10", "selects no")]:
        result = CliRunner().invoke(app, ["plan", "drone", "-o", str(out), "--roi", roi])
        assert result.exit_code == 2
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and message in lines[0] and "--roi" in lines[0]
        assert not out.exists()


def test_cli_plan_evaluate_scan_keep_to_the_roi(tmp_path):
    import json

    stl, csv, ply = tmp_path / "p.stl", tmp_path / "t.csv", tmp_path / "c.ply"
    plate_with_block().mesh.export(stl)
    roi = ["--roi", BLOCK_BOX + ";+z:10"]
    run = CliRunner().invoke
    assert run(app, ["plan", str(stl), "-o", str(csv), *roi]).exit_code == 0
    result = run(app, ["evaluate", str(stl), str(csv), "--json", "--points", "256", *roi])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["in_spec_coverage"] > 0.97
    assert data["visible_area_mm2"] == pytest.approx(300 * 200, rel=0.02)
    assert run(app, ["scan", str(stl), str(csv), "-o", str(ply), *roi]).exit_code == 0
    points = trimesh.load(ply).vertices
    assert len(points) and np.allclose(points[:, 2], 60.0, atol=0.5)


def test_evaluate_perturbed_zero_is_nominal_and_bad_specs_are_one_line(plate_file, tmp_path):
    traj = tmp_path / "t.csv"
    write_csv(straight(np.arange(150.0, 350.0, 0.5)), traj)
    base = ["evaluate", str(plate_file), str(traj), "--points", "64"]
    zero = "place:0mm,0deg;warp:0mm@200mm;path:0mm"
    result = runner.invoke(app, [*base, "--json", "--perturb", zero, "--trials", "1"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    robust = data["robustness"]
    assert robust["nominal"] == data["in_spec_coverage"] == robust["worst"] == robust["mean"]
    assert robust["trials"] == 1 and robust["per_trial"] == [robust["mean"]]
    for bad, message in [
        (["--perturb", "warp:1mm"], "error: --perturb term 'warp:1mm': expected an RMS"),
        (["--perturb", "path:1mm", "--trials", "0"], "--trials"),
        (["--scheduler", "tcp://127.0.0.1:1"], "--scheduler runs --perturb's trials"),
        (["--perturb", "path:1mm", "--scheduler", "nowhere"], "expected tcp://HOST:PORT"),
    ]:
        result = runner.invoke(app, [*base, *bad])
        assert result.exit_code == 2 and message in result.output, result.output
        assert result.output.strip().count("\n") == 0


def test_evaluate_closed_loop_runs_a_feedback_plan_and_refuses_the_others(plate_file, tmp_path):
    plans = {}
    for planner in ("feedback", "fixed"):
        plans[planner] = tmp_path / f"{planner}.json"
        args = ["plan", str(plate_file), "--planner", planner, "--no-roll", "-q"]
        result = runner.invoke(app, [*args, "-o", str(plans[planner])])
        assert result.exit_code == 0, result.output
    loop = ["--perturb", "place:0mm", "--trials", "1", "--closed-loop"]
    base = ["evaluate", str(plate_file), str(plans["feedback"]), "--points", "64", "-q"]
    result = runner.invoke(app, [*base, "--json", *loop])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["robustness"]["loop"] == "closed"
    assert data["robustness"]["per_trial"] == [data["in_spec_coverage"]]
    fixed = ["evaluate", str(plate_file), str(plans["fixed"]), "--points", "64"]
    for args, message in [
        ([*fixed, *loop], "--closed-loop re-runs the controller of a feedback or rl plan"),
        ([*base, "--closed-loop"], "--closed-loop runs --perturb's trials"),
        ([*base, "--policy", "v1"], "--policy is the rl plan's policy for --closed-loop"),
        ([*base, *loop, "--policy", "v1"], "--policy is the rl plan's policy"),
    ]:
        result = runner.invoke(app, args)
        assert result.exit_code == 2 and message in result.output, result.output
        assert result.output.strip().count("\n") == 0


def test_plan_a_folder_of_parts_on_two_processes_and_on_dask(tmp_path):
    # A catalogue: each part planned as `plan` plans it alone, a bad part is its own one-line
    # failure (the others still planned, exit 1), and a Dask cluster plans the same.
    folder = tmp_path / "parts"
    folder.mkdir()
    trimesh.creation.box((300.0, 150.0, 20.0)).export(folder / "block.stl")
    trimesh.creation.box((200.0, 120.0, 10.0)).export(folder / "plate.ply")
    (folder / "broken.stl").write_text("solid x\nnot an stl\n")
    (folder / "notes.txt").write_text("not a part")
    opts = ["--planner", "fixed", "-q"]
    result = runner.invoke(app, ["plan", str(folder), "-o", str(tmp_path / "plans"), *opts])
    assert result.exit_code == 1
    assert "broken.stl: error: " in result.stderr and "1 of 3 parts not planned" in result.stderr
    assert "block.stl: fixed: 1 view" in result.stdout and "-> " in result.stdout
    alone = tmp_path / "block_alone.json"
    assert (
        runner.invoke(app, ["plan", str(folder / "block.stl"), "-o", str(alone), *opts]).exit_code
        == 0
    )
    by_catalogue = read_trajectory(tmp_path / "plans" / "block.json")
    assert np.array_equal(by_catalogue.poses, read_trajectory(alone).poses)
    assert (tmp_path / "plans" / "plate.json").is_file()
    (folder / "broken.stl").unlink()
    if importlib.util.find_spec("distributed") is not None:
        with loopback_cluster() as cluster:
            out = tmp_path / "on_dask"
            args = ["plan", str(folder), "-o", str(out), "--scheduler", cluster.scheduler_address]
            result = runner.invoke(app, [*args, *opts])
        assert result.exit_code == 0, result.output
        assert np.array_equal(read_trajectory(out / "block.json").poses, by_catalogue.poses)
    for bad, message in (
        (["-o", str(tmp_path / "x.json")], "-o is the folder the plans go to"),
        (["-o", str(tmp_path / "empty_out")], "holds no part file"),
    ):
        target = folder if "x.json" in bad[1] else tmp_path / "plans"  # a folder of plans only
        result = runner.invoke(app, ["plan", str(target), *bad, *opts])
        assert result.exit_code == 2 and message in result.stderr
    alone_scheduler = ["plan", str(folder / "block.stl"), "-o", str(alone), "--scheduler", "x"]
    result = runner.invoke(app, alone_scheduler)
    assert result.exit_code == 2 and "expected tcp://HOST:PORT" in result.stderr


@pytest.mark.skipif(
    importlib.util.find_spec("distributed") is None, reason="dask distributed not installed"
)
def test_one_part_s_views_planned_on_dask_are_those_planned_here(tmp_path):
    part = tmp_path / "overhang.stl"
    overhang_part().mesh.export(part)
    here = tmp_path / "here.json"
    assert runner.invoke(app, ["plan", str(part), "-o", str(here), "-q"]).exit_code == 0
    with loopback_cluster(threads=2) as cluster:
        on_dask = tmp_path / "dask.json"
        args = ["plan", str(part), "-o", str(on_dask), "--scheduler", cluster.scheduler_address]
        result = runner.invoke(app, [*args, "-q"])
        assert result.exit_code == 0, result.output
        top = ["plan", str(part), "-o", str(tmp_path / "top.json"), "--views", "top"]
        refused = runner.invoke(app, [*top, "--scheduler", cluster.scheduler_address])
    assert refused.exit_code == 2
    assert "--scheduler plans the candidate views of --views auto" in refused.stderr
    planned, there = read_trajectory(here), read_trajectory(on_dask)
    assert len(planned.meta["views"]) > 2
    assert np.array_equal(planned.poses, there.poses)


def test_plan_a_list_of_parts_as_a_folder_is_planned(tmp_path):
    # A .txt list: one path a line, relative to the list, # comments; each part planned as
    # `plan` plans it alone, a bad entry its own one-line failure, the rest still planned.
    parts = tmp_path / "cad"
    (parts / "sub").mkdir(parents=True)
    trimesh.creation.box((300.0, 150.0, 20.0)).export(parts / "sub" / "block.stl")
    trimesh.creation.box((200.0, 120.0, 10.0)).export(tmp_path / "plate.ply")
    listing = parts / "catalogue.txt"
    listing.write_text(
        "# parts of cell 3\n"
        "sub/block.stl   # the block\n"
        "\n"
        f"{tmp_path / 'plate.ply'}\n"
        "missing.stl\n"
        "not-a-part\n"
    )
    opts = ["--planner", "fixed", "-q"]
    out = tmp_path / "plans"
    result = runner.invoke(app, ["plan", str(listing), "-o", str(out), *opts])
    assert result.exit_code == 1
    errors = result.stderr.strip().splitlines()
    assert errors[0].startswith("missing.stl: error: part file ") and "does not exist" in errors[0]
    assert errors[1].startswith("not-a-part: error: part 'not-a-part' is neither a file")
    assert errors[2] == "error: 2 of 4 parts not planned" and len(errors) == 3
    assert "sub/block.stl: fixed: 1 view" in result.stdout
    assert sorted(p.name for p in out.iterdir()) == ["block.json", "plate.json"]
    alone = tmp_path / "block_alone.json"
    args = ["plan", str(parts / "sub" / "block.stl"), "-o", str(alone), *opts]
    assert runner.invoke(app, args).exit_code == 0
    assert np.array_equal(read_trajectory(out / "block.json").poses, read_trajectory(alone).poses)
    for text, message in (
        ("# nothing\n\n", "names no part"),
        ("a/block.stl\nb/block.obj\n", "parts block would share a plan name"),
    ):
        listing.write_text(text)
        result = runner.invoke(app, ["plan", str(listing), "-o", str(tmp_path / "p2"), *opts])
        assert result.exit_code == 2 and message in result.stderr
        assert result.stderr.strip().count("\n") == 0 and not (tmp_path / "p2").exists()
    result = runner.invoke(app, ["plan", str(tmp_path / "none.txt"), "-o", str(out), *opts])
    assert (
        result.exit_code == 2 and "part list" in result.stderr and "does not exist" in result.stderr
    )


def test_one_part_on_a_scheduler_without_dask_is_refused_in_one_line(tmp_path, monkeypatch):
    real = importlib.util.find_spec

    def without_dask(name, *args):
        return None if name == "distributed" else real(name, *args)

    monkeypatch.setattr(importlib.util, "find_spec", without_dask)
    out = tmp_path / "p.json"
    result = runner.invoke(app, ["plan", "door", "-o", str(out), "--scheduler", "tcp://h:8786"])
    assert result.exit_code == 2
    assert "--scheduler needs the cluster extra" in result.stderr
    assert result.stderr.strip().count("\n") == 0 and not out.exists()
