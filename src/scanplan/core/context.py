"""What a plan was made under, carried by its file: the sensor, the scan's parameters, the
step limits, the planner, the views, the region of interest and the surface to inspect. A
plan evaluated from its CSV or its JSON is judged the same way, as it was planned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Annotated, Any, Literal, TypeVar

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from scanplan.core.limits import (
    ANGLE_DEG,
    CLEARANCE_MM,
    MAX_SCAN_SPEED_MM_S,
    ORIENTATION_ERROR_DEG,
    PROFILE_RATE_HZ,
    REWARD_WEIGHT,
    SPEED_MM_S,
    STEP_MM,
    TOLERANCE_MM,
    in_range,
)
from scanplan.core.quantities import ScanSpec, StepLimits
from scanplan.core.sensor_files import sensor_datasheet, sensor_from_datasheet
from scanplan.core.trajectory import Trajectory
from scanplan.core.validation import error_line

FORMAT = "scanplan-plan/1"
# The table through the part's lowest point (`--table`'s default).
LOWEST = "lowest"
VIEW_MODES = ("top", "auto")


@dataclass(frozen=True)
class PlanContext:
    """A plan's context. roi: the `--roi` text (None: the part's own surface to inspect);
    full_beam_angle: the orientation reward charges the whole angle between the beam and
    the mean normal (a planner that rolls, env v1) rather than the pitch error (env v0)."""

    spec: ScanSpec = field(default_factory=ScanSpec)
    limits: StepLimits = field(default_factory=StepLimits)
    planner: str = ""
    views: str = "top"
    roi: str | None = None
    full_beam_angle: bool = False
    # The cell, as `cell.Cell.around` takes it: the `--table` text and the fixture files.
    table: str = LOWEST
    fixtures: tuple[str, ...] = ()
    fixture_units: str = "mm"  # the --units of the part's and the fixtures' files
    # The part planned: a built-in name or the file as given ('' where not recorded), so
    # that `export` checks the arm's links against it.
    part: str = ""
    # `world.part.geometry_digest` of the part as planned ('' where not recorded): a part
    # judged or flown by this plan must be this one.
    part_digest: str = ""

    def __post_init__(self) -> None:
        if self.views not in VIEW_MODES:
            raise ValueError(f"unknown --views {self.views!r}; use top or auto")

    @property
    def surface(self) -> str:
        """The surface to inspect: `top` what a sensor looking straight down can see,
        `hemisphere` what it can see from the upper hemisphere, `roi` the region of interest
        (seen from the views allowed)."""
        if self.roi:
            return "roi"
        return "hemisphere" if self.views == "auto" else "top"

    @property
    def visible(self) -> str:
        """Where the surface is seen from: 'top' or 'hemisphere' (an ROI: its views')."""
        return "hemisphere" if self.views == "auto" else "top"

    def to_json_dict(self) -> dict[str, Any]:
        spec, lim = self.spec, self.limits
        return {
            "format": FORMAT,
            "planner": self.planner,
            "views": self.views,
            "surface": self.surface,
            "roi": self.roi,
            "reward": "full beam angle (v1)" if self.full_beam_angle else "pitch (v0)",
            "table": self.table,
            "fixtures": list(self.fixtures),
            "fixture_units": self.fixture_units,
            "part": self.part,
            "part_digest": self.part_digest,
            **scan_spec_record(spec),
            "step_limits": {
                "dy_max_mm": lim.dy_max_mm,
                "dz_max_mm": lim.dz_max_mm,
                "dtheta_max_deg": math.degrees(lim.dtheta_max_rad),
                "dphi_max_deg": math.degrees(lim.dphi_max_rad),
            },
        }

    @classmethod
    def from_json_dict(cls, data: object, where: str) -> PlanContext:
        """The context a plan file records; ValueError naming `where` and the field."""
        model = _validated(_ContextJson, data, f"{where}: context")
        spec = _scan_spec(model.sensor, model.scan_spec, f"{where}: context")
        lim = model.step_limits
        try:
            limits = StepLimits(
                lim.dy_max_mm,
                lim.dz_max_mm,
                math.radians(lim.dtheta_max_deg),
                math.radians(lim.dphi_max_deg),
            )
            return cls(
                spec,
                limits,
                model.planner,
                model.views,
                model.roi,
                model.reward.startswith("full"),
                model.table,
                tuple(model.fixtures),
                model.fixture_units,
                model.part,
                model.part_digest,
            )
        except ValueError as exc:
            raise ValueError(f"{where}: context: {exc}") from None

    def differences(self, other: PlanContext) -> list[str]:
        """What `other` (a command's options) changes from this plan's context, in words."""
        out = []
        if sensor_datasheet(other.spec.sensor) != sensor_datasheet(self.spec.sensor):
            out.append(f"sensor {other.spec.sensor.name} (planned: {self.spec.sensor.name})")
        a, b = self.spec, other.spec
        if (a.tolerance_mm, a.tol_angle_rad) != (b.tolerance_mm, b.tol_angle_rad):
            out.append(
                f"tolerance {b.tolerance_mm:g} mm, {math.degrees(b.tol_angle_rad):g}° "
                f"(planned: {a.tolerance_mm:g} mm, {math.degrees(a.tol_angle_rad):g}°)"
            )
        if other.roi != self.roi:
            out.append(f"region of interest {other.roi or 'none'} (planned: {self.roi or 'none'})")
        if other.surface != self.surface:
            out.append(f"surface {other.surface} (planned: {self.surface})")
        if (other.table, other.fixtures) != (self.table, self.fixtures):
            out.append(
                f"table {other.table}, fixtures {list(other.fixtures)} (planned: table "
                f"{self.table}, fixtures {list(self.fixtures)})"
            )
        return out

    def with_options(
        self,
        spec: ScanSpec | None = None,
        roi: str | None = None,
        views: str | None = None,
        table: str | None = None,
        fixtures: tuple[str, ...] | None = None,
    ) -> PlanContext:
        """This context with what a command's options override (None: as planned)."""
        return replace(
            self,
            spec=self.spec if spec is None else spec,
            roi=self.roi if roi is None else (roi or None),
            views=self.views if views is None else views,
            table=self.table if table is None else table,
            fixtures=self.fixtures if fixtures is None else fixtures,
        )


def scan_spec_record(spec: ScanSpec) -> dict[str, Any]:
    """The ScanSpec as a file records it: the sensor's datasheet and the scan's parameters
    (read back by `scan_spec_from_record`)."""
    return {
        "sensor": sensor_datasheet(spec.sensor),
        "scan_spec": {
            "delta_s_opt_mm": spec.delta_s_opt_mm,
            "alpha_max_deg": math.degrees(spec.alpha_max_rad),
            "weights": [spec.w_d, spec.w_alpha, spec.w_delta_s],
            "tolerance_mm": spec.tolerance_mm,
            "tolerance_deg": math.degrees(spec.tol_angle_rad),
            "profile_rate_hz": spec.profile_rate_hz,
            "travel_speed_mm_s": spec.travel_speed_mm_s,
            "clearance_mm": spec.clearance_mm,
        },
    }


def scan_spec_from_record(data: object, where: str) -> ScanSpec:
    """The ScanSpec a file records (`scan_spec_record`); ValueError naming where and what."""
    model = _validated(_SpecRecordJson, data, where)
    return _scan_spec(model.sensor, model.scan_spec, where)


def _validated(schema: type[_Json], data: object, where: str) -> _Json:
    """`data` checked against `schema`; ValueError naming where and the first bad field."""
    try:
        return schema.model_validate(data)
    except ValidationError as exc:
        raise ValueError(error_line(where, exc)) from None


def _scan_spec(sensor_data: dict[str, Any], s: _ScanSpecJson, where: str) -> ScanSpec:
    sensor = sensor_from_datasheet(sensor_data, f"{where}: sensor")
    try:
        return ScanSpec(
            sensor=sensor,
            delta_s_opt_mm=s.delta_s_opt_mm,
            alpha_max_rad=math.radians(s.alpha_max_deg),
            w_d=s.weights[0],
            w_alpha=s.weights[1],
            w_delta_s=s.weights[2],
            tol_distance_mm=s.tolerance_mm,
            tol_angle_rad=math.radians(s.tolerance_deg),
            profile_rate_hz=s.profile_rate_hz,
            travel_speed_mm_s=s.travel_speed_mm_s,
            clearance_mm=s.clearance_mm,
        )
    except ValueError as exc:
        raise ValueError(f"{where}: scan_spec: {exc}") from None


_STRICT = ConfigDict(extra="forbid", strict=True)
_Json = TypeVar("_Json", bound=BaseModel)
# A plan file's numbers in the ranges the same values have as options (`core.limits`).
Step = Annotated[float, in_range(STEP_MM)]
StepAngle = Annotated[float, in_range(ANGLE_DEG)]
OrientationError = Annotated[float, in_range(ORIENTATION_ERROR_DEG)]
Weight = Annotated[float, in_range(REWARD_WEIGHT)]


class _ScanSpecJson(BaseModel):
    model_config = _STRICT
    delta_s_opt_mm: Step
    alpha_max_deg: OrientationError
    weights: Annotated[list[Weight], Field(min_length=3, max_length=3)]
    tolerance_mm: Annotated[float, in_range(TOLERANCE_MM)]
    tolerance_deg: OrientationError
    profile_rate_hz: Annotated[float, in_range(PROFILE_RATE_HZ)]
    travel_speed_mm_s: Annotated[float, in_range(SPEED_MM_S)]
    clearance_mm: Annotated[float, in_range(CLEARANCE_MM)]

    @model_validator(mode="after")
    def _a_scan_speed_an_arm_flies(self) -> _ScanSpecJson:
        speed = self.profile_rate_hz * self.delta_s_opt_mm
        if speed > MAX_SCAN_SPEED_MM_S:
            raise ValueError(
                f"profile_rate_hz {self.profile_rate_hz:g} x delta_s_opt_mm "
                f"{self.delta_s_opt_mm:g}: a scan speed of {speed:g} mm/s, more than the "
                f"{MAX_SCAN_SPEED_MM_S:g} allowed"
            )
        if sum(self.weights) <= 0:
            raise ValueError("weights: all 0; the reward needs one > 0")
        return self


class _LimitsJson(BaseModel):
    model_config = _STRICT
    dy_max_mm: Step
    dz_max_mm: Step
    dtheta_max_deg: StepAngle
    dphi_max_deg: StepAngle


class _SpecRecordJson(BaseModel):
    model_config = _STRICT
    sensor: dict[str, Any]
    scan_spec: _ScanSpecJson


class _ContextJson(BaseModel):
    model_config = _STRICT
    format: Literal["scanplan-plan/1"]
    planner: str
    views: Literal["top", "auto"]
    surface: Literal["top", "hemisphere", "roi"]
    roi: str | None
    reward: str
    table: str = LOWEST
    fixtures: list[str] = []
    fixture_units: Literal["mm", "m", "in"] = "mm"
    part: str = ""
    part_digest: str = ""
    sensor: dict[str, Any]
    scan_spec: _ScanSpecJson
    step_limits: _LimitsJson


def judged_alike(contexts: list[PlanContext]) -> list[PlanContext]:
    """Several plans of one part judged on one surface: the widest any of them inspects (what
    the upper hemisphere sees, if any was planned with views), each keeping its own reward."""
    views = "auto" if any(c.views == "auto" for c in contexts) else "top"
    return [replace(c, views=views) for c in contexts]


def recorded(traj: Trajectory, spec: ScanSpec) -> PlanContext:
    """The context a trajectory records (`meta["context"]`); for one without (a file from
    elsewhere), `spec` and the surface its views imply: hemisphere for several views."""
    data = traj.meta.get("context")
    if data is not None:
        return PlanContext.from_json_dict(data, f"plan of {traj.planner or 'unknown planner'}")
    views = "auto" if len(traj.meta.get("views") or ()) > 1 else "top"
    return PlanContext(spec, planner=traj.planner, views=views)
