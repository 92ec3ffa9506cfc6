"""User files, read and validated in one place: sensor datasheets (TOML or YAML).

A sensor file gives datasheet values in the units an engineer reads off the datasheet
(mm, degrees, µm for the Z resolution), for example:

    name = "my-sensor"
    working_distance_mm = 300
    z_range_mm = 200
    fov_deg = 45
    points_per_profile = 2048
    z_resolution_um = 2.5
    triangulation_angle_deg = 30
    camera_side = "+y"          # or "-y"
    incidence_cutoff_deg = 80
    [noise]                      # optional; `noise = false` switches noise off
    sigma0_um = 4
    speckle_amplitude_um = 15
    speckle_scale_mm = 0.5
    seed = 0
    [body]                       # optional; the sensor body box in the sensor frame, mm
    x_mm = [-50, 50]             # default; y_mm from -40 to b + 40 on the camera side
    z_mm = [-90, 0]              # (b = W_d tan(gamma)); an axis left out keeps its default
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import replace
from pathlib import Path
from typing import Annotated, Literal

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from scanplan.core.limits import (
    FOV_DEG,
    INCIDENCE_CUTOFF_DEG,
    LENGTH_MM,
    MAX_PROFILE_POINTS,
    MAX_SEED,
    NOISE_UM,
    SENSOR_BODY_MM,
    SPECKLE_SCALE_MM,
    TRIANGULATION_DEG,
    WORKING_DISTANCE_MM,
    Z_RESOLUTION_UM,
    Limit,
    in_range,
)
from scanplan.core.noise import NoiseModel
from scanplan.core.paths import read_regular, regular_file
from scanplan.core.sensor_spec import PRESETS, SensorSpec
from scanplan.core.validation import first_error

# Strict: "300" or true where a number belongs is a mistake in the file, not a value to coerce.
_STRICT = ConfigDict(extra="forbid", strict=True)
MAX_SENSOR_FILE_BYTES = 1024**2


class NoiseFile(BaseModel):
    model_config = _STRICT
    sigma0_um: Annotated[float, in_range(NOISE_UM)] = 4.0
    speckle_amplitude_um: Annotated[float, in_range(NOISE_UM)] = 15.0
    speckle_scale_mm: Annotated[float, in_range(SPECKLE_SCALE_MM)] = 0.5
    seed: Annotated[int, in_range(Limit(0, MAX_SEED))] = 0


Interval = Annotated[
    list[Annotated[float, in_range(SENSOR_BODY_MM)]], Field(min_length=2, max_length=2)
]


class BodyFile(BaseModel):
    """The sensor body box in the sensor frame, mm; an axis left out keeps the default."""

    model_config = _STRICT
    x_mm: Interval | None = None
    y_mm: Interval | None = None
    z_mm: Interval | None = None

    @model_validator(mode="after")
    def _min_below_max(self) -> BodyFile:
        for axis in ("x_mm", "y_mm", "z_mm"):
            interval = getattr(self, axis)
            if interval is not None and not interval[0] < interval[1]:
                raise ValueError(f"{axis}: min must be < max, got {interval}")
            # A body thinner than a millimetre is a typing slip, not a sensor.
            if interval is not None and not interval[1] - interval[0] >= 1.0:
                raise ValueError(f"{axis}: {interval} is less than 1 mm wide")
        return self


class SensorFile(BaseModel):
    """Every number in the range of `scanplan.core.limits` a real sensor can have."""

    model_config = _STRICT
    name: str = "custom"
    working_distance_mm: Annotated[float, in_range(WORKING_DISTANCE_MM)]
    z_range_mm: Annotated[float, in_range(LENGTH_MM)]
    fov_deg: Annotated[float, in_range(FOV_DEG)]
    points_per_profile: Annotated[int, in_range(Limit(2, MAX_PROFILE_POINTS))]
    z_resolution_um: Annotated[float, in_range(Z_RESOLUTION_UM, or_zero=True)]
    triangulation_angle_deg: Annotated[float, in_range(TRIANGULATION_DEG)]
    camera_side: Literal["+y", "-y"] = "+y"
    incidence_cutoff_deg: Annotated[float, in_range(INCIDENCE_CUTOFF_DEG)] = 80.0
    noise: NoiseFile | bool = True
    body: BodyFile | None = None

    @field_validator("working_distance_mm", mode="before")
    @classmethod
    def _metres_hint(cls, value: object) -> object:
        if isinstance(value, int | float) and 0 < value < WORKING_DISTANCE_MM.lo:
            raise ValueError(
                f"{value:g} is not in {WORKING_DISTANCE_MM} (a value in metres? give millimetres)"
            )
        return value

    @model_validator(mode="after")
    def _range_within_distance(self) -> SensorFile:
        if self.z_range_mm >= 2 * self.working_distance_mm:
            raise ValueError("z_range_mm must be less than twice working_distance_mm")
        return self

    def to_spec(self) -> SensorSpec:
        noise: NoiseModel | None
        if self.noise is False:
            noise = None
        else:
            nf = self.noise if isinstance(self.noise, NoiseFile) else NoiseFile.model_validate({})
            noise = NoiseModel(
                sigma0_mm=nf.sigma0_um / 1000,
                speckle_amplitude_mm=nf.speckle_amplitude_um / 1000,
                speckle_scale_mm=nf.speckle_scale_mm,
                seed=nf.seed,
            )
        spec = SensorSpec(
            name=self.name,
            working_distance_mm=self.working_distance_mm,
            z_range_mm=self.z_range_mm,
            fov_rad=math.radians(self.fov_deg),
            points_per_profile=self.points_per_profile,
            z_resolution_mm=self.z_resolution_um / 1000,
            triangulation_angle_rad=math.radians(self.triangulation_angle_deg),
            camera_side=1 if self.camera_side == "+y" else -1,
            incidence_cutoff_rad=math.radians(self.incidence_cutoff_deg),
            noise=noise,
        )
        if self.body is None:
            return spec
        default = spec.body_bounds_mm
        given = [self.body.x_mm, self.body.y_mm, self.body.z_mm]
        box = default.copy()
        for axis, interval in enumerate(given):
            if interval is not None:
                box[:, axis] = interval
        (x0, y0, z0), (x1, y1, z1) = box.tolist()
        return replace(spec, body_min_mm=(x0, y0, z0), body_max_mm=(x1, y1, z1))


def _first_error(what: str, exc: ValidationError) -> str:
    # A union (noise: table | bool) names its branch in the location: drop those.
    where, message = first_error(exc, ("NoiseFile", "bool", "BodyFile"), record="a table")
    return f"{what}: {where or 'file'}: {message}"


def load_sensor(spec: str | Path) -> SensorSpec:
    """A preset name or a TOML/YAML sensor file -> SensorSpec; ValueError saying what/where.

    YAML is read with `yaml.safe_load`: tags such as !!python/object never run code.
    """
    text = str(spec)
    if text in PRESETS:
        return PRESETS[text]
    path = Path(text)
    if not (path.exists() or path.is_symlink()):
        raise ValueError(f"sensor {text!r} is neither a file nor a preset ({', '.join(PRESETS)})")
    regular_file(path, "sensor file")  # a directory, a FIFO, a device: said as such
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".yaml", ".yml"):
        raise ValueError(f"sensor file {path}: use a .toml, .yaml or .yml file")
    content = read_regular(path, "sensor file", MAX_SENSOR_FILE_BYTES, "not a sensor datasheet")
    try:
        raw = content.decode("utf-8-sig")
        data = tomllib.loads(raw) if suffix == ".toml" else yaml.safe_load(raw)
    except RecursionError:
        raise ValueError(f"sensor file {path} cannot be parsed: nested too deeply") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, yaml.YAMLError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(f"sensor file {path} cannot be parsed: {first}") from None
    return sensor_from_datasheet(data, f"sensor file {path}")


def sensor_datasheet(spec: SensorSpec) -> dict:
    """The sensor as a sensor file would give it (datasheet units): what a plan file records,
    read back by `sensor_from_datasheet` into the same sensor."""
    data: dict = {
        "name": spec.name,
        "working_distance_mm": spec.working_distance_mm,
        "z_range_mm": spec.z_range_mm,
        "fov_deg": math.degrees(spec.fov_rad),
        "points_per_profile": spec.points_per_profile,
        "z_resolution_um": spec.z_resolution_mm * 1000,
        "triangulation_angle_deg": math.degrees(spec.triangulation_angle_rad),
        "camera_side": "+y" if spec.camera_side > 0 else "-y",
        "incidence_cutoff_deg": math.degrees(spec.incidence_cutoff_rad),
        "noise": False,
    }
    if spec.body_min_mm is not None and spec.body_max_mm is not None:
        data["body"] = {
            f"{axis}_mm": [float(spec.body_min_mm[i]), float(spec.body_max_mm[i])]
            for i, axis in enumerate("xyz")
        }
    if spec.noise is not None:
        data["noise"] = {
            "sigma0_um": spec.noise.sigma0_mm * 1000,
            "speckle_amplitude_um": spec.noise.speckle_amplitude_mm * 1000,
            "speckle_scale_mm": spec.noise.speckle_scale_mm,
            "seed": spec.noise.seed,
        }
    return data


def sensor_from_datasheet(data: object, where: str) -> SensorSpec:
    """A sensor from its datasheet values (as `sensor_datasheet` gives them, or a parsed
    sensor file); ValueError naming `where` and the field."""
    if not isinstance(data, dict):
        raise ValueError(f"{where}: expected a table of datasheet values")
    try:
        return SensorFile.model_validate(data).to_spec()
    except ValidationError as exc:
        raise ValueError(_first_error(where, exc)) from None
    except ValueError as exc:  # SensorSpec's own checks
        raise ValueError(f"{where}: {exc}") from None
