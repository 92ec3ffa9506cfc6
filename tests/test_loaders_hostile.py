"""Hostile input to every loader: arbitrary bytes and arbitrary structured values end in a
ValueError with a one-line message (or a valid result), never another exception; and through
the command line, exit code 2, one line on stderr, no traceback, no output file."""

from __future__ import annotations

import json
import math
import os
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from scanplan.cli import app
from scanplan.config import load_sensor
from scanplan.part import load_part
from scanplan.trajectory import (
    CSV_COLUMNS,
    Trajectory,
    dumps_json,
    read_trajectory,
    write_csv,
)

FAST = settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


def _one_line_or_ok(load, path: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy RuntimeWarning noise either
        try:
            load(path)
        except ValueError as exc:
            message = str(exc)
            assert message and "\n" not in message, message
            assert str(path) in message or path.name in message, message


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
    _one_line_or_ok(load_part, path)


@pytest.mark.parametrize("suffix", [".csv", ".json"])
@FAST
@given(content=st.binary(max_size=600))
def test_trajectory_files_of_arbitrary_bytes(tmp_path, suffix, content):
    path = tmp_path / f"t{suffix}"
    path.write_bytes(content)
    _one_line_or_ok(read_trajectory, path)


@pytest.mark.parametrize("suffix", [".toml", ".yaml"])
@FAST
@given(content=st.binary(max_size=600))
def test_sensor_files_of_arbitrary_bytes(tmp_path, suffix, content):
    path = tmp_path / f"s{suffix}"
    path.write_bytes(content)
    _one_line_or_ok(load_sensor, path)


# ---- arbitrary structured values ----------------------------------------------------------
SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
)
JSON_VALUES = st.recursive(
    SCALARS,
    lambda inner: st.one_of(
        st.lists(inner, max_size=5), st.dictionaries(st.text(max_size=8), inner, max_size=5)
    ),
    max_leaves=30,
)
POSE_KEYS = ["swath", "scanning", "position_mm", "quaternion_wxyz"]


def _pose_like() -> st.SearchStrategy[dict]:
    good = {
        "swath": 0,
        "scanning": True,
        "position_mm": [0, 0, 400],
        "quaternion_wxyz": [1, 0, 0, 0],
    }
    return st.dictionaries(st.sampled_from(POSE_KEYS + ["extra"]), JSON_VALUES, max_size=5).map(
        lambda d: {**good, **d}
    )


@FAST
@given(
    doc=st.one_of(
        JSON_VALUES,
        st.fixed_dictionaries(
            {"poses": st.lists(_pose_like(), max_size=4)},
            optional={"planner": JSON_VALUES, "plan_time_s": JSON_VALUES},
        ),
    )
)
def test_trajectory_json_of_arbitrary_values(tmp_path, doc):
    path = tmp_path / "t.json"
    path.write_text(json.dumps(doc))
    _one_line_or_ok(read_trajectory, path)


SENSOR_KEYS = [
    "name",
    "working_distance_mm",
    "z_range_mm",
    "fov_deg",
    "points_per_profile",
    "z_resolution_um",
    "triangulation_angle_deg",
    "camera_side",
    "incidence_cutoff_deg",
    "noise",
    "body",
]
GOOD_SENSOR = {
    "working_distance_mm": 300,
    "z_range_mm": 200,
    "fov_deg": 45,
    "points_per_profile": 64,
    "z_resolution_um": 2,
    "triangulation_angle_deg": 30,
}


@FAST
@given(
    overrides=st.dictionaries(st.sampled_from(SENSOR_KEYS), JSON_VALUES, max_size=4),
    drop=st.sets(st.sampled_from(list(GOOD_SENSOR)), max_size=2),
)
def test_sensor_yaml_of_arbitrary_values(tmp_path, overrides, drop):
    doc = {k: v for k, v in {**GOOD_SENSOR, **overrides}.items() if k not in drop}
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(doc))
    _one_line_or_ok(load_sensor, path)


@FAST
@given(value=JSON_VALUES)
def test_json_safe_always_gives_valid_json(value):
    text = dumps_json(value)

    def refuse(literal: str) -> None:
        raise AssertionError(f"{literal} in {text}")

    json.loads(text, parse_constant=refuse)  # no NaN/Infinity literal anywhere


def test_json_safe_on_numpy():
    out = json.loads(dumps_json({"a": np.array([1.0, np.nan]), "b": np.int64(3), "c": math.inf}))
    assert out == {"a": [1.0, None], "b": 3, "c": None}


# ---- the command line ---------------------------------------------------------------------
runner = CliRunner()


@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    d = tmp_path_factory.mktemp("hostile")
    files = {
        "lying.stl": b"\0" * 80 + struct.pack("<I", 1000) + b"\0" * 50,
        "random.obj": os.urandom(200),
        "badidx.ply": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
        b"property float y\nproperty float z\nelement face 1\n"
        b"property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n",
        "huge.stl": b"\0" * 80
        + struct.pack("<I", 1)
        + struct.pack("<12f", 0, 0, 1, 0, 0, 0, 1e30, 0, 0, 0, 1e30, 0)
        + b"\0\0",
        "empty.step": b"",
        "bad.step": b"ISO-10303-21;\nnonsense\n",
        "deep.json": b"[" * 50_000 + b"]" * 50_000,
        "swath.csv": (",".join(CSV_COLUMNS) + "\n1e20,1,0,0,400,1,0,0,0\n").encode(),
        "nanq.json": json.dumps(
            {
                "poses": [
                    {
                        "swath": 0,
                        "scanning": True,
                        "position_mm": [0, 0, 400],
                        "quaternion_wxyz": [0, 0, 0, 0],
                    }
                ]
            }
        ).encode(),
        "metres.toml": b"working_distance_mm = 0.4\nz_range_mm = 0.25\nfov_deg = 63.5\n"
        b"points_per_profile = 64\nz_resolution_um = 3.8\ntriangulation_angle_deg = 30\n",
        "tag.yaml": b"!!python/object/apply:os.system ['touch "
        + str(d / "PWNED").encode()
        + b"']\n",
    }
    for name, content in files.items():
        (d / name).write_bytes(content)
    plate = d / "plate.stl"
    import trimesh

    box = trimesh.creation.box((300, 300, 10))
    box.export(plate)
    poses = np.tile(np.diag([1.0, -1.0, -1.0, 1.0]), (5, 1, 1))
    poses[:, :3, 3] = np.c_[np.linspace(-20, 20, 5), np.zeros(5), np.full(5, 405.0)]
    write_csv(Trajectory(poses, np.zeros(5, int), np.ones(5, bool)), d / "good.csv")
    return d


CLI_CASES = [
    ("plan", "{d}/lying.stl", "-o", "{out}.csv"),
    ("plan", "{d}/random.obj", "-o", "{out}.csv"),
    ("plan", "{d}/badidx.ply", "-o", "{out}.csv"),
    ("plan", "{d}/huge.stl", "-o", "{out}.csv"),
    ("plan", "{d}/empty.step", "-o", "{out}.csv"),
    ("plan", "{d}/bad.step", "-o", "{out}.json"),
    ("plan", "{d}/plate.stl", "--sensor", "{d}/metres.toml", "-o", "{out}.csv"),
    ("plan", "{d}/plate.stl", "--sensor", "{d}/tag.yaml", "-o", "{out}.csv"),
    ("plan", "{d}", "-o", "{out}.csv"),
    ("evaluate", "{d}/plate.stl", "{d}/deep.json", "-o", "{out}"),
    ("evaluate", "{d}/plate.stl", "{d}/swath.csv", "--json"),
    ("scan", "{d}/plate.stl", "{d}/nanq.json", "-o", "{out}.ply"),
    ("scan", "{d}/huge.stl", "{d}/good.csv", "-o", "{out}.ply"),
    ("export", "{d}/swath.csv", "--format", "urscript", "-o", "{out}.script"),
    ("export", "{d}/deep.json", "--format", "krl", "-o", "{out}.src"),
]


@pytest.mark.parametrize("args", CLI_CASES, ids=lambda a: "-".join(Path(x).name for x in a[:3]))
def test_cli_hostile_input_is_one_line_exit_2_no_output(hostile, tmp_path, args):
    out = tmp_path / "out"
    argv = [a.format(d=hostile, out=out) for a in args]
    result = runner.invoke(app, argv)
    assert result.exit_code == 2, (result.stdout, result.stderr, result.exception)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert "Traceback" not in result.output and "Warning" not in result.output
    assert list(tmp_path.iterdir()) == []  # no partial output of any kind
    assert not (hostile / "PWNED").exists()
