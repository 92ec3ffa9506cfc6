"""Sensor files (config.load_sensor): the preset, TOML and YAML datasheets, and bad input of any
shape in one line naming the file and the field."""

from __future__ import annotations

import math

import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from helpers import FAST, JSON_VALUES, one_line_or_ok
from scanplan.core.sensor_files import load_sensor
from scanplan.core.sensor_spec import PRESETS

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
        (("working_distance_mm = 300", "working_distance_mm = inf"), r"inf is not in \[10, 5000\]"),
        (("fov_deg = 45", "fov_deg = nan"), r"fov_deg: nan is not in \[0.1, 170\) deg"),
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


@pytest.mark.parametrize("suffix", [".toml", ".yaml"])
@FAST
@given(content=st.binary(max_size=600))
def test_sensor_files_of_arbitrary_bytes(tmp_path, suffix, content):
    path = tmp_path / f"s{suffix}"
    path.write_bytes(content)
    one_line_or_ok(load_sensor, path)


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
    one_line_or_ok(load_sensor, path)
