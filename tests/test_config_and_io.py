"""Sensor files, part loading, trajectory files: bad input says what and where."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import trimesh

from scanplan.config import load_sensor
from scanplan.part import load_part
from scanplan.sensor import PRESETS
from scanplan.swaths import Swath
from scanplan.trajectory import Trajectory, read_csv, read_json, write_csv, write_json

GOOD_TOML = """
name = "my-sensor"
working_distance_mm = 300
z_range_mm = 200
fov_deg = 45
points_per_profile = 2048
z_resolution_um = 2.5
triangulation_angle_deg = 25
camera_side = "-y"
[noise]
sigma0_um = 3
"""


def test_preset_matches_the_datasheet():
    spec = load_sensor("at-c5-4090cs30-495")
    assert spec is PRESETS["at-c5-4090cs30-495"]
    assert spec.working_distance_mm == 400
    assert spec.z_range_mm == 250
    assert math.degrees(spec.fov_rad) == pytest.approx(63.5)
    assert spec.points_per_profile == 4096
    assert spec.z_resolution_mm == pytest.approx(0.0038)
    assert spec.line_width_mm == pytest.approx(495.0, abs=0.5)


def test_toml_and_yaml_sensor_files(tmp_path):
    toml = tmp_path / "s.toml"
    toml.write_text(GOOD_TOML)
    spec = load_sensor(toml)
    assert spec.working_distance_mm == 300
    assert spec.camera_side == -1
    assert spec.noise is not None and spec.noise.sigma0_mm == pytest.approx(0.003)
    assert spec.z_resolution_mm == pytest.approx(0.0025)
    yml = tmp_path / "s.yaml"
    yml.write_text(
        "working_distance_mm: 300\nz_range_mm: 200\nfov_deg: 45\npoints_per_profile: 64\n"
        "z_resolution_um: 2\ntriangulation_angle_deg: 30\nnoise: false\n"
    )
    assert load_sensor(yml).noise is None


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (GOOD_TOML.replace("fov_deg = 45", "fov_deg = 200"), "fov_deg"),
        (GOOD_TOML.replace("z_range_mm = 200", "z_range_mm = 700"), "z_range_mm"),
        (GOOD_TOML.replace("points_per_profile = 2048", ""), "points_per_profile"),
        (GOOD_TOML + "\ncolour = 'red'\n", "colour"),
        ("working_distance_mm = = 3", "cannot be parsed"),
    ],
)
def test_invalid_sensor_files_say_what_and_where(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message) as err:
        load_sensor(path)
    assert str(path) in str(err.value)
    assert "\n" not in str(err.value)


def test_unknown_sensor():
    with pytest.raises(ValueError, match="neither a file nor a preset"):
        load_sensor("no-such-sensor")


def test_mesh_units_and_scene_merge(tmp_path):
    a = trimesh.creation.box((0.2, 0.1, 0.05))
    b = trimesh.creation.box((0.1, 0.1, 0.1))
    b.apply_translation((0.5, 0, 0))
    scene = trimesh.Scene([a, b])
    path = tmp_path / "two_bodies.glb"
    scene.export(path)
    part = load_part(path, units="m")
    assert part.extents[0] == pytest.approx(650.0, rel=1e-6)
    assert len(part.mesh.faces) == 24
    stl = tmp_path / "block.stl"
    trimesh.creation.box((2.0, 1.0, 0.5)).export(stl)
    assert load_part(stl, units="in").extents == pytest.approx([50.8, 25.4, 12.7])


def test_bad_meshes_fail_clearly(tmp_path):
    corrupt = tmp_path / "corrupt.stl"
    corrupt.write_bytes(b"solid x\nfacet normal 0 0 1\n garbage\n")
    with pytest.raises(ValueError, match="corrupt.stl"):
        load_part(corrupt)
    with pytest.raises(ValueError, match="does not exist"):
        load_part(tmp_path / "missing.stl")
    with pytest.raises(ValueError, match="neither a file nor a built-in part"):
        load_part("no-such-part")
    flat = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]], process=False)
    path = tmp_path / "degenerate.ply"
    flat.export(path)
    with pytest.raises(ValueError, match="degenerate|empty"):
        load_part(path)
    tiny = tmp_path / "tiny.stl"
    trimesh.creation.box((0.1, 0.1, 0.1)).export(tiny)
    with pytest.raises(ValueError, match="check --units"):
        load_part(tiny, units="mm")
    nan = trimesh.creation.box((10, 10, 10))
    nan.vertices[0] = np.nan
    path = tmp_path / "nan.ply"
    nan.export(path)
    with pytest.raises(ValueError, match="non-finite|cannot be read|empty|degenerate"):
        load_part(path)


def _trajectory() -> Trajectory:
    sw = Swath(0, np.array([0.0, 5, 400]), np.array([100.0, 5, 400]), np.eye(3)[0], np.eye(3)[1])
    poses = sw.poses(np.linspace(0, 100, 11), np.linspace(0, 3, 11), np.linspace(-0.2, 0.2, 11))
    swath = np.r_[np.zeros(6, int), np.ones(5, int)]
    return Trajectory(poses, swath, np.arange(11) != 5, planner="test")


def test_trajectory_csv_and_json_round_trip(tmp_path):
    traj = _trajectory()
    write_csv(traj, tmp_path / "t.csv")
    back = read_csv(tmp_path / "t.csv")
    assert np.allclose(back.poses, traj.poses, atol=1e-6)
    assert np.array_equal(back.swath, traj.swath)
    assert np.array_equal(back.scanning, traj.scanning)
    header = (tmp_path / "t.csv").read_text().splitlines()[0]
    assert header == "swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz"
    write_json(traj, tmp_path / "t.json")
    assert np.allclose(read_json(tmp_path / "t.json").poses, traj.poses, atol=1e-9)


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("", "empty"),
        ("a,b,c\n1,2,3\n", "line 1: header"),
        ("swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz\n", "no poses"),
        ("swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz\n0,1,0,0,400,1,0,0\n", "line 2: expected 9"),
        ("swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz\n0,1,0,0,x,1,0,0,0\n", "z_mm: not a number"),
        ("swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz\n0,1,0,0,nan,1,0,0,0\n", "non-finite"),
        ("swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz\n0,1,0,0,4,0,0,0,0\n", "zero length"),
        ("swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz\n0,3,0,0,4,1,0,0,0\n", "scanning column"),
    ],
)
def test_malformed_trajectory_files(tmp_path, body, message):
    path = tmp_path / "bad.csv"
    path.write_text(body)
    with pytest.raises(ValueError, match=message):
        read_csv(path)


def test_atomic_write_leaves_no_temporary_and_a_readable_file(tmp_path):
    import os

    from scanplan.trajectory import atomic_write_text

    old = os.umask(0o022)
    try:
        atomic_write_text(tmp_path / "out.txt", "hello\n")
    finally:
        os.umask(old)
    assert (tmp_path / "out.txt").read_text() == "hello\n"
    assert (tmp_path / "out.txt").stat().st_mode & 0o777 == 0o644  # not mkstemp's 0600
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_sensor_body_default_from_the_datasheet(tmp_path):
    lo, hi = PRESETS["at-c5-4090cs30-495"].body_bounds_mm
    assert lo == pytest.approx([-50, -40, -90])
    assert hi == pytest.approx([50, 400 * math.tan(math.radians(30)) + 40, 0])
    assert hi[1] == pytest.approx(271, abs=0.1)  # camera on +y
    path = tmp_path / "s.toml"
    path.write_text(GOOD_TOML + "[body]\nx_mm = [-70, 70]\n")
    spec = load_sensor(path)  # camera on -y: the body reaches towards -y
    lo, hi = spec.body_bounds_mm
    assert lo[0] == -70 and hi[0] == 70
    assert lo[1] == pytest.approx(-(300 * math.tan(math.radians(25)) + 40)) and hi[1] == 40


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (("working_distance_mm = 300", "working_distance_mm = 0.3"), "metres"),
        (("working_distance_mm = 300", "working_distance_mm = 6000"), "working_distance_mm"),
        (("working_distance_mm = 300", "working_distance_mm = inf"), "finite"),
        (("fov_deg = 45", "fov_deg = nan"), "fov_deg: Input should be a finite"),
        (("fov_deg = 45", "fov_deg = 175"), "fov_deg"),
        (("points_per_profile = 2048", "points_per_profile = 200000"), "points_per_profile"),
        (("points_per_profile = 2048", "points_per_profile = 20.5"), "points_per_profile"),
        (("sigma0_um = 3", "sigma0_um = -3"), "noise.sigma0_um"),
        (("sigma0_um = 3", "seed = -1"), "noise.seed"),
        (("sigma0_um = 3", "seed = 1.5"), "noise.seed"),
        (("sigma0_um = 3", "seed = true"), "noise.seed"),
        (("sigma0_um = 3", "sigma0_um = '3'"), "noise.sigma0_um"),
        (("[noise]", "[body]\nx_mm = [50, -50]\n[noise]"), "body: x_mm: min must be < max"),
        (("[noise]", "[body]\nz_mm = [-inf, 0]\n[noise]"), "body.z_mm"),
    ],
)
def test_implausible_sensor_values_name_the_field(tmp_path, edit, message):
    path = tmp_path / "bad.toml"
    assert edit[0] in GOOD_TOML
    path.write_text(GOOD_TOML.replace(*edit))
    with pytest.raises(ValueError, match=message) as err:
        load_sensor(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_yaml_python_tags_run_nothing(tmp_path):
    marker = tmp_path / "PWNED"
    for text in (
        f"!!python/object/apply:os.system ['touch {marker}']\n",
        f"working_distance_mm: !!python/object/apply:os.system ['touch {marker}']\n",
    ):
        path = tmp_path / "evil.yaml"
        path.write_text(text)
        with pytest.raises(ValueError, match="cannot be parsed") as err:
            load_sensor(path)
        assert "\n" not in str(err.value)
    assert not marker.exists()


def test_sensor_spec_refuses_non_finite_and_implausible_values():
    import dataclasses

    base = PRESETS["at-c5-4090cs30-495"]
    for change in (
        {"working_distance_mm": math.nan},
        {"fov_rad": math.inf},
        {"working_distance_mm": 0.4},
        {"points_per_profile": 100_001},
        {"body_min_mm": (0, 0, 0), "body_max_mm": (1, -1, 1)},
        {"body_min_mm": (0, 0, 0)},
    ):
        with pytest.raises(ValueError, match="sensor"):
            dataclasses.replace(base, **change)


def test_a_single_triangle_plate_loads_and_plans(tmp_path):
    from scanplan.pipeline import plan_path
    from scanplan.planners import make_planner
    from scanplan.quantities import ScanSpec
    from scanplan.swaths import plan_swaths

    path = tmp_path / "tri.stl"
    trimesh.Trimesh([[0, 0, 0], [200, 0, 0], [0, 100, 0]], [[0, 1, 2]]).export(path)
    part = load_part(path)
    spec = PRESETS["at-c5-4090cs30-495"].without_noise().with_points(64)
    traj = plan_path(part, ScanSpec(spec), make_planner("fixed"), plan_swaths(part, spec))
    assert traj.scanning.sum() > 10


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("empty.stl", b"", "empty"),
        ("lying.stl", b"\0" * 80 + (1000).to_bytes(4, "little") + b"\0" * 100, "announces 1000"),
        ("short.stl", b"\1\2\3", "not an STL"),
        ("line.stl", None, "degenerate"),
        ("missing.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "OBJ"),
        ("noise.glb", b"glTF\2\0\0\0" + b"\0" * 40, "GLB"),
        ("latin1.obj", b"# caf\xe9\nv 0 0 0\nv 100 0 0\nv 0 100 0\nf 1 2 3\n", None),
    ],
)
def test_corrupt_mesh_files_say_what(tmp_path, name, content, message):
    path = tmp_path / name
    if content is None:  # three collinear points
        trimesh.Trimesh([[0, 0, 0], [50, 0, 0], [100, 0, 0]], [[0, 1, 2]], process=False).export(
            path
        )
    else:
        path.write_bytes(content)
    if message is None:
        assert len(load_part(path).mesh.faces) == 1
        return
    with pytest.raises(ValueError, match=message) as err:
        load_part(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_a_huge_mesh_file_is_refused_before_reading(tmp_path):
    path = tmp_path / "huge.stl"
    with open(path, "wb") as f:  # sparse: no disk used
        f.truncate(3 * 1024**3)
    with pytest.raises(ValueError, match="GiB"):
        load_part(path)


def test_trajectory_json_fields_are_checked(tmp_path):
    traj = _trajectory()
    write_json(traj, tmp_path / "t.json")
    good = json.loads((tmp_path / "t.json").read_text())
    cases = [
        ({"planner": 3}, "planner"),
        ({"plan_time_s": "fast"}, "plan_time_s"),
        ({"poses": [{**good["poses"][0], "position_mm": [0, 0]}]}, r"poses\[0\].position_mm"),
        ({"poses": [{**good["poses"][0], "swath": 10**20}]}, r"poses\[0\].swath"),
        ({"poses": [{**good["poses"][0], "scanning": "yes"}]}, r"poses\[0\].scanning"),
        ({"poses": [{**good["poses"][0], "quaternion_wxyz": [0, 0, 0, 0]}]}, "zero length"),
        ({"poses": []}, "poses"),
    ]
    for change, message in cases:
        path = tmp_path / "bad.json"
        path.write_text(json.dumps({**good, **change}))
        with pytest.raises(ValueError, match=message) as err:
            read_json(path)
        assert str(path) in str(err.value) and "\n" not in str(err.value)
    path.write_text(json.dumps({**good, "plan_time_s": math.nan}))  # Python's json writes NaN
    with pytest.raises(ValueError, match="plan_time_s"):
        read_json(path)
    path.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ValueError, match="nested too deeply"):
        read_json(path)


def test_json_writer_never_writes_nan(tmp_path):
    traj = _trajectory()
    write_json(Trajectory(traj.poses, traj.swath, traj.scanning, planner="p"), tmp_path / "t.json")
    text = (tmp_path / "t.json").read_text()
    assert "NaN" not in text and "Infinity" not in text


def test_trajectory_csv_with_bom_and_swath_overflow(tmp_path):
    traj = _trajectory()
    write_csv(traj, tmp_path / "t.csv")
    text = (tmp_path / "t.csv").read_text()
    (tmp_path / "bom.csv").write_text("\ufeff" + text)
    assert len(read_csv(tmp_path / "bom.csv")) == len(traj)
    lines = text.splitlines()
    lines[3] = "1e20" + lines[3][lines[3].index(",") :]
    (tmp_path / "big.csv").write_text("\n".join(lines))
    with pytest.raises(ValueError, match="line 4, column swath"):
        read_csv(tmp_path / "big.csv")
    with pytest.raises(ValueError, match="32-bit"):
        Trajectory(traj.poses, np.full(len(traj), 1e20), traj.scanning)
