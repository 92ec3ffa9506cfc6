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
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from scanplan.noise import NoiseModel
from scanplan.sensor import PRESETS, SensorSpec


class NoiseFile(BaseModel):
    model_config = ConfigDict(extra="forbid")
    sigma0_um: float = Field(4.0, ge=0)
    speckle_amplitude_um: float = Field(15.0, ge=0)
    speckle_scale_mm: float = Field(0.5, gt=0)
    seed: int = 0


class SensorFile(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str = "custom"
    working_distance_mm: float = Field(gt=0)
    z_range_mm: float = Field(gt=0)
    fov_deg: float = Field(gt=0, lt=180)
    points_per_profile: int = Field(ge=2, le=100_000)
    z_resolution_um: float = Field(ge=0)
    triangulation_angle_deg: float = Field(gt=0, lt=90)
    camera_side: Literal["+y", "-y"] = "+y"
    incidence_cutoff_deg: float = Field(80.0, gt=0, le=90)
    noise: NoiseFile | bool = True

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
        return SensorSpec(
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


def _first_error(path: Path, exc: ValidationError) -> str:
    err = exc.errors()[0]
    where = ".".join(str(p) for p in err["loc"]) or "file"
    return f"sensor file {path}: {where}: {err['msg']}"


def load_sensor(spec: str | Path) -> SensorSpec:
    """A preset name or a TOML/YAML sensor file -> SensorSpec; ValueError saying what/where."""
    text = str(spec)
    if text in PRESETS:
        return PRESETS[text]
    path = Path(text)
    if not path.is_file():
        raise ValueError(f"sensor {text!r} is neither a file nor a preset ({', '.join(PRESETS)})")
    try:
        raw = path.read_text()
        if path.suffix.lower() == ".toml":
            data = tomllib.loads(raw)
        elif path.suffix.lower() in (".yaml", ".yml"):
            data = yaml.safe_load(raw)
        else:
            raise ValueError(f"sensor file {path}: use a .toml, .yaml or .yml file")
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, yaml.YAMLError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f"sensor file {path} cannot be parsed: {first}") from None
    if not isinstance(data, dict):
        raise ValueError(f"sensor file {path}: expected a table of datasheet values")
    try:
        return SensorFile.model_validate(data).to_spec()
    except ValidationError as exc:
        raise ValueError(_first_error(path, exc)) from None
