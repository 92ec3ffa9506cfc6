"""Parts (part.py): mesh and STEP files loaded in mm with the file's unit honoured, bad files in
one line, whatever their bytes (SPEC §6).

The STEP fixtures under tests/data are made by tests/data/make_step_fixtures.py (gmsh's
OpenCASCADE); the volumes below are analytic."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
import trimesh
from hypothesis import given
from hypothesis import strategies as st

from helpers import DATA, FAST, one_line_or_ok
from scanplan.core.quantities import ScanSpec
from scanplan.core.sensor_spec import PRESETS, SensorSpec
from scanplan.planning.pass_path import plan_path
from scanplan.planning.swaths import plan_swaths
from scanplan.rl.planners import make_planner
from scanplan.world.part import load_part


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


def test_a_single_triangle_plate_loads_and_plans(tmp_path):
    from scanplan.core.quantities import ScanSpec
    from scanplan.planning.pass_path import plan_path
    from scanplan.planning.swaths import plan_swaths
    from scanplan.rl.planners import make_planner

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


# ---- arbitrary bytes with every suffix -----------------------------------------------------
MESH_SUFFIXES = [".stl", ".obj", ".ply", ".off", ".glb", ".step"]


def _headed(suffix: str) -> st.SearchStrategy[bytes]:
    """Bytes that get past the first check of each format, so the parsers are exercised."""
    heads = {
        ".stl": [b"solid x\n", b"\0" * 80 + struct.pack("<I", 1)],
        ".obj": [b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf "],
        ".ply": [b"ply\nformat ascii 1.0\nelement vertex 3\n", b"ply\nformat binary_little_endian"],
        ".off": [b"OFF\n3 1 0\n"],
        ".glb": [b"glTF\x02\x00\x00\x00"],
        ".step": [b"ISO-10303-21;\nHEADER;\n"],
    }
    return st.tuples(st.sampled_from(heads[suffix]), st.binary(max_size=400)).map(
        lambda t: t[0] + t[1]
    )


@pytest.mark.parametrize("suffix", MESH_SUFFIXES)
@FAST
@given(data=st.data())
def test_mesh_files_of_arbitrary_bytes(tmp_path, suffix, data):
    content = data.draw(st.one_of(st.binary(max_size=600), _headed(suffix)))
    path = tmp_path / f"part{suffix}"
    path.write_bytes(content)
    one_line_or_ok(load_part, path)


def _rounded_box_volume(a: float, b: float, c: float, r: float) -> float:
    """A box with every edge and corner rounded to radius r."""
    x, y, z = a - 2 * r, b - 2 * r, c - 2 * r
    return (
        x * y * z
        + 2 * r * (x * y + y * z + x * z)
        + math.pi * r * r * (x + y + z)
        + (4 / 3 * math.pi * r**3)
    )


@pytest.mark.parametrize(
    ("name", "extents", "volume"),
    [
        ("box", (200, 100, 50), 200 * 100 * 50),
        ("filleted_box", (120, 80, 40), _rounded_box_volume(120, 80, 40, 10)),
        ("plate_with_holes", (300, 200, 10), 300 * 200 * 10 - 4 * math.pi * 15**2 * 10),
        ("small_box_in", (3 * 25.4, 2 * 25.4, 25.4), 6 * 25.4**3),  # the file is in inches
        ("small_box_m", (3000, 2000, 1000), 6e9),  # the file is in metres
    ],
)
def test_step_parts_load_in_mm_with_the_right_size_and_volume(name, extents, volume):
    part = load_part(DATA / f"{name}.step")
    assert part.extents == pytest.approx(extents, rel=1e-6)
    assert part.mesh.is_watertight
    assert part.mesh.volume == pytest.approx(volume, rel=1e-3)
    assert (part.mesh.area_faces > 0).all()  # degenerate triangles dropped


def test_step_units_option_does_not_rescale_a_step_file():
    # The STEP file carries its own unit; --units is for unit-less mesh formats.
    assert load_part(DATA / "box.step", units="in").extents == pytest.approx((200, 100, 50))


def test_tessellation_is_bounded_by_the_part_size():
    # Deflection max(0.01 mm, 1e-3 x diagonal) and 0.2 rad: the fillets stay a small mesh.
    part = load_part(DATA / "filleted_box.step")
    assert len(part.mesh.faces) < 20_000


@pytest.mark.parametrize(
    "content",
    [b"", b"ISO-10303-21;\nHEADER;\nnot really\n", bytes(range(256)) * 4, b"\xff\xfe\x00\x00"],
)
@pytest.mark.parametrize("suffix", [".step", ".stp"])
def test_corrupt_or_empty_step_is_one_line(tmp_path, capfd, content, suffix):
    path = tmp_path / f"bad{suffix}"
    path.write_bytes(content)
    with pytest.raises(ValueError) as err:
        load_part(path)
    message = str(err.value)
    assert str(path) in message and "\n" not in message
    out, errors = capfd.readouterr()
    assert out == "" and errors == ""  # OpenCASCADE's own complaints are not printed


def test_a_step_part_can_be_planned():
    part = load_part(DATA / "plate_with_holes.step")
    spec = SensorSpec().without_noise().with_points(64)
    swaths = plan_swaths(part, spec)
    traj = plan_path(part, ScanSpec(spec), make_planner("fixed"), swaths)
    assert len(swaths) == 1 and traj.scanning.sum() > 100
    assert np.isfinite(traj.poses).all()
    # the fixed planner flies at W_d above the plate's top face (z = 10 mm)
    assert np.median(traj.positions_mm[traj.scanning, 2]) == pytest.approx(410.0, abs=1.0)


def test_a_step_file_read_only_in_part_is_refused(tmp_path, capfd):
    # Bytes garbled inside one entity: OpenCASCADE skips it and returns a box missing a face.
    data = (DATA / "box.step").read_bytes()
    at = data.index(b"#26 = ") + 10
    bad = tmp_path / "garbled.step"
    bad.write_bytes(data[:at] + b"}}{{ 7 ?? !! ((" + data[at:])
    with pytest.raises(ValueError, match="read only in part") as err:
        load_part(bad)
    assert "\n" not in str(err.value) and str(bad) in str(err.value)
    out, stderr = capfd.readouterr()
    assert out == "" and stderr == ""  # OpenCASCADE's own report captured


@pytest.mark.parametrize("factor", [b"-25.4", b"0.", b"abc"])
def test_a_step_length_unit_that_is_not_a_positive_length_is_refused(tmp_path, factor):
    data = (DATA / "small_box_in.step").read_bytes()
    bad = tmp_path / "mirrored.step"
    bad.write_bytes(data.replace(b"LENGTH_MEASURE(25.4)", b"LENGTH_MEASURE(" + factor + b")"))
    with pytest.raises(ValueError, match="not a positive length"):
        load_part(bad)
