"""Issue 26, property tests over `scanplan.core.limits`: any value outside a plausibility range ends
in one line naming the field, the value and the range; any value inside passes the check, and
a sensor file of in-range values measures a profile without a warning.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Annotated

import pytest
import trimesh
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel, ValidationError
from typer.testing import CliRunner

import scanplan.core.limits as limits
from scanplan.cli import app
from scanplan.core.limits import Limit, in_range
from scanplan.core.sensor_files import sensor_from_datasheet
from scanplan.robot.presets import RobotFile

# Small: the validators are cheap, but the whole file stays well under 20 s.
QUICK = settings(
    max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
RANGES = {name: v for name, v in vars(limits).items() if isinstance(v, Limit)}


def outside(limit: Limit) -> st.SearchStrategy[float]:
    """Values no real cell has: below lo, above hi (an open end included), and NaN, ±inf."""
    below = st.floats(max_value=limit.lo, exclude_max=not limit.lo_open, allow_nan=False)
    above = st.floats(min_value=limit.hi, exclude_min=not limit.hi_open, allow_nan=False)
    return st.one_of(below, above, st.sampled_from([math.nan, math.inf, -math.inf]))


def inside(limit: Limit) -> st.SearchStrategy[float]:
    return st.floats(
        limit.lo, limit.hi, exclude_min=limit.lo_open, exclude_max=limit.hi_open, allow_nan=False
    )


def test_every_range_is_a_range():
    assert len(RANGES) >= 20
    for name, limit in RANGES.items():
        assert limit.lo < limit.hi, name
        assert math.isfinite(limit.lo) and math.isfinite(limit.hi), name


@pytest.mark.parametrize("name", sorted(RANGES))
@QUICK
@given(data=st.data())
def test_a_value_outside_is_one_line_naming_field_value_and_range(name, data):
    limit = RANGES[name]
    value = data.draw(outside(limit))
    with pytest.raises(ValueError) as err:
        limit.check(value, "the field")
    message = str(err.value)
    assert "\n" not in message and message.startswith("the field ")
    assert str(limit) in message


@pytest.mark.parametrize("name", sorted(RANGES))
@QUICK
@given(data=st.data())
def test_a_value_inside_passes(name, data):
    limit = RANGES[name]
    value = data.draw(inside(limit))
    assert limit.check(value, "the field") == value


@QUICK
@given(st.integers(min_value=2**32, max_value=10**5000) | st.integers(max_value=-1))
def test_an_integer_too_long_for_a_float_is_refused_not_crashed(value):
    with pytest.raises(ValueError, match=r"^seed .* is not in \[0, 4294967295\]$"):
        Limit(0, limits.MAX_SEED).check(value, "seed")


class _Model(BaseModel):
    length_mm: Annotated[float, in_range(limits.LENGTH_MM)]


@QUICK
@given(outside(limits.LENGTH_MM))
def test_in_range_gives_pydantic_the_value_and_the_range(value):
    with pytest.raises(ValidationError) as err:
        _Model(length_mm=value)
    first = err.value.errors()[0]
    assert first["loc"] == ("length_mm",)
    assert str(limits.LENGTH_MM) in first["msg"] and "\n" not in first["msg"]


# ---- the file loaders: each field against its range -----------------------------------------
SENSOR = {
    "working_distance_mm": 300.0,
    "z_range_mm": 200.0,
    "fov_deg": 45.0,
    "points_per_profile": 64,
    "z_resolution_um": 2.5,
    "triangulation_angle_deg": 30.0,
    "incidence_cutoff_deg": 80.0,
}
SENSOR_FIELDS = {
    "working_distance_mm": limits.WORKING_DISTANCE_MM,
    "z_range_mm": limits.LENGTH_MM,
    "fov_deg": limits.FOV_DEG,
    "z_resolution_um": limits.Z_RESOLUTION_UM,
    "triangulation_angle_deg": limits.TRIANGULATION_DEG,
    "incidence_cutoff_deg": limits.INCIDENCE_CUTOFF_DEG,
    "noise.sigma0_um": limits.NOISE_UM,
    "noise.speckle_amplitude_um": limits.NOISE_UM,
    "noise.speckle_scale_mm": limits.SPECKLE_SCALE_MM,
    "body.x_mm": limits.SENSOR_BODY_MM,
}


def _sensor_with(field: str, value: float) -> dict:
    data = {**SENSOR, "noise": {"sigma0_um": 4.0}}
    if field == "body.x_mm":
        data["body"] = {"x_mm": [value, 10.0] if value < 0 else [-10.0, value]}
    elif field.startswith("noise."):
        data["noise"][field.removeprefix("noise.")] = value
    else:
        data[field] = value
    return data


@pytest.mark.parametrize("field", sorted(SENSOR_FIELDS))
@QUICK
@given(data=st.data())
def test_a_sensor_file_field_outside_its_range_is_one_line_naming_it(field, data):
    value = data.draw(outside(SENSOR_FIELDS[field]))
    assume(not (field == "z_resolution_um" and value == 0))  # no resolution limit: allowed
    with pytest.raises(ValueError) as err:
        sensor_from_datasheet(_sensor_with(field, value), "sensor file s.toml")
    message = str(err.value)
    assert "\n" not in message and message.startswith("sensor file s.toml: ")
    assert field.split(".")[-1] in message


@pytest.fixture(scope="module")
def plate():
    from scanplan.world.part import part_from_mesh

    mesh = trimesh.creation.box((400.0, 400.0, 10.0))
    mesh.apply_translation((0, 0, -5))
    return part_from_mesh(mesh, "plate")


@settings(QUICK, max_examples=25)
@given(
    wd=inside(limits.WORKING_DISTANCE_MM),
    fov=inside(limits.FOV_DEG),
    tri=inside(limits.TRIANGULATION_DEG),
    cutoff=inside(limits.INCIDENCE_CUTOFF_DEG),
    zres=inside(limits.Z_RESOLUTION_UM) | st.just(0.0),
    sigma=inside(limits.NOISE_UM),
    amplitude=inside(limits.NOISE_UM),
    scale=inside(limits.SPECKLE_SCALE_MM),
    share=st.floats(1e-3, 0.99),
)
def test_a_sensor_of_in_range_values_measures_without_a_warning(
    plate, wd, fov, tri, cutoff, zres, sigma, amplitude, scale, share
):
    import numpy as np

    from scanplan.sensor.profilometer import LineProfilometer

    z_range = 2 * wd * share
    assume(limits.LENGTH_MM.contains(z_range))
    data = {
        "working_distance_mm": wd,
        "z_range_mm": z_range,
        "fov_deg": fov,
        "points_per_profile": 32,
        "z_resolution_um": zres,
        "triangulation_angle_deg": tri,
        "incidence_cutoff_deg": cutoff,
        "noise": {"sigma0_um": sigma, "speckle_amplitude_um": amplitude, "speckle_scale_mm": scale},
    }
    spec = sensor_from_datasheet(data, "sensor file s.toml")
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])  # the laser down at the plate
    T[2, 3] = wd
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        profile = LineProfilometer(plate, spec).measure(T)
    assert np.isfinite(profile.z_sensor[profile.valid]).all()


ROBOT = {
    "a1": 25.0,
    "a2": -35.0,
    "c1": 400.0,
    "c2": 455.0,
    "c3": 420.0,
    "c4": 80.0,
    "limits_deg": [[-170, 170]] * 6,
}
ROBOT_FIELDS = {
    **{f: limits.SIGNED_LENGTH_MM for f in ("a1", "a2", "b", "c1", "c3")},
    "c2": limits.LINK_MM,
    "speed_mm_s": limits.SPEED_MM_S,
    "accel_mm_s2": limits.TCP_ACCEL_MM_S2,
    "angular_speed_deg_s": limits.TURN_SPEED_DEG_S,
    "angular_accel_deg_s2": limits.TURN_ACCEL_DEG_S2,
}


@pytest.mark.parametrize("field", sorted(ROBOT_FIELDS))
@QUICK
@given(data=st.data())
def test_a_robot_file_field_outside_its_range_names_it(field, data):
    value = data.draw(outside(ROBOT_FIELDS[field]))
    with pytest.raises(ValidationError) as err:
        RobotFile.model_validate({**ROBOT, field: value})
    first = err.value.errors()[0]
    assert first["loc"][0] == field and str(ROBOT_FIELDS[field]) in first["msg"]


@pytest.mark.parametrize("field", sorted(ROBOT_FIELDS))
@QUICK
@given(data=st.data())
def test_a_robot_file_field_inside_its_range_loads(field, data):
    value = data.draw(inside(ROBOT_FIELDS[field]))
    if field in ("a2", "c3"):  # the forearm hypot(a2, c3) is a link too
        other = ROBOT["c3" if field == "a2" else "a2"]
        assume(limits.LINK_MM.contains(math.hypot(value, other)))
    RobotFile.model_validate({**ROBOT, field: value}).to_robot()


@QUICK
@given(x=outside(limits.POSITION_MM))
def test_a_trajectory_position_outside_names_the_line_and_column(tmp_path_factory, x):
    from scanplan.core.plan_file import read_csv

    path = Path(tmp_path_factory.mktemp("t")) / "t.csv"
    row = "0,1,{},0,400,0,0.707106781,0.707106781,0\n"
    path.write_text("swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz\n" + row.format(0) + row.format(x))
    with pytest.raises(ValueError) as err:
        read_csv(path)
    message = str(err.value)
    assert "\n" not in message and f"{path} line 3, column x_mm" in message


# ---- one cheap CLI path: an option checked against its range before any work ------------------
runner = CliRunner()


@settings(QUICK, max_examples=5)
@given(spacing=outside(limits.STEP_MM))
def test_export_spacing_outside_is_one_line_naming_the_option(tmp_path_factory, spacing):
    out = Path(tmp_path_factory.mktemp("o")) / "p.script"
    args = ["export", "t.csv", "-o", str(out), "--robot", "none", "--spacing", repr(spacing)]
    result = runner.invoke(app, args)
    assert result.exit_code == 2
    assert len(result.stderr.splitlines()) == 1 and "--spacing" in result.stderr
    assert not out.exists()
