"""What `evaluate` reports: the summary of one trajectory's simulated scan, the in-spec map
of the surface to inspect, and the definitions the JSON carries beside the figures.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np

from scanplan.core.cycle import CycleTime
from scanplan.core.files import json_safe
from scanplan.sensor.cloud import PointCloud
from scanplan.world.surface import CEILING_BEAMS, COVERAGE_MAX_SLOPE_DEG, VIEW_AXIS_MAX_TILT_DEG

COVERAGE_DEFINITION = (
    "fraction of the surface to inspect (`surface`) sampled by valid points: that surface is "
    "sampled uniformly by area (seeded) and a sample kept if it can be seen - `top`: its face "
    f"is within {COVERAGE_MAX_SLOPE_DEG:.0f} deg of horizontal and a vertical ray from it "
    "escapes the part; `hemisphere`: the same along at least one direction of the upper "
    "hemisphere; `roi`: either, on the region of interest only; it is covered if a valid "
    "measured point lies within `coverage_radius_mm` of it (about the spacing of the "
    "measured columns)"
)
IN_SPEC_COVERAGE_DEFINITION = (
    "fraction of the same samples of the surface to inspect that have, within "
    "`in_spec_radius_mm`, "
    "a measured point that is valid, has |z_s - W_d| <= tol_d and alpha_i <= tol_alpha "
    "(`tolerance`), lies on the sample's side of the surface (its normal within 45° of the "
    "sample's outward normal: a point on a sheet's top does not measure its underside, nor "
    "one on a flat the wall below its edge), and lies where the real scan samples the "
    "surface at least once per "
    "(2 delta_s_opt)^2: on the surface, at the point's distance, the real sensor's spacing is "
    "<= 2 delta_s_opt both along the pass (the column's displacement to its neighbouring "
    "profiles of the pass, the larger of the two) and across it (the real sensor's column "
    "pitch, not the evaluation's sub-sampled fan). The radius is half the diagonal of a cell "
    "2 delta_s_opt long and one evaluated column pitch wide (at the far tolerance depth and "
    "tilt), so a sub-sampled fan still reaches every sample between its columns, while "
    "profiles sparser than 2 delta_s_opt fail however wide the radius"
)

VISIBILITY_CEILING_DEFINITION = (
    "fraction of the same samples of the surface to inspect that some beam reaches "
    "unobstructed from within tol_alpha of the face's normal and at most "
    f"{VIEW_AXIS_MAX_TILT_DEG:.0f} deg from vertical (the normal and {CEILING_BEAMS - 1} seeded "
    "directions in that cone tried per sample): no plan holds more of the surface in spec. "
    "It ignores the depth window, the sensor body and the camera's line of sight, so plans "
    "stay below it; `in_spec_of_ceiling` is in-spec coverage divided by it"
)


class SurfaceState(IntEnum):
    """What the scan did to one sample of the surface to inspect."""

    UNSEEN = 0  # no valid point near it
    OUT_OF_SPEC = 1  # seen, but by no in-spec point (distance, angle or density)
    IN_SPEC = 2


@dataclass(frozen=True)
class CoverageMap:
    """The in-spec map: area-uniform samples of the surface to inspect and their state.

    points_part: (k, 3) float64, mm.  state: (k,) int8, a `SurfaceState` per sample.
    """

    points_part: np.ndarray
    state: np.ndarray

    def fraction(self, state: SurfaceState) -> float:
        return float((self.state == state).mean()) if len(self.state) else 0.0


@dataclass(frozen=True)
class Metrics:
    """SPEC §7 summary of one trajectory's simulated scan. Lengths mm, angles degrees.

    Distance error per point: z_s − W_d; orientation error per point: α_i = acos(−z_s·n_i).
    Spacing: Δs (`quantities.advance`) between consecutive profiles of the same pass;
    `pairs_without_overlap` pairs share no valid column and are left out of the spacing stats.
    Rewards: per step (a profile and its predecessor in the pass), `reward.reward_terms`.
    Coverage: see `COVERAGE_DEFINITION`; in-spec coverage (the headline figure): see
    `IN_SPEC_COVERAGE_DEFINITION`, at the tolerances `tolerance_mm`, `tolerance_deg` and at
    least one point per `in_spec_cell_mm`² (2·Δs_opt). `visibility_ceiling`: the most of the
    same samples any plan could hold in spec (`VISIBILITY_CEILING_DEFINITION`; None if not
    measured), and `in_spec_of_ceiling` the in-spec coverage as a share of it.
    Cycle time: `cycle` (`scanplan.core.cycle.CycleTime`, its model and the arm's limits);
    `cycle_time_s`, `scan_time_s`, `move_time_s` its total, passes and moves.
    Collisions (every pose, scanning or not; `collision.CellChecker`): poses whose sensor
    body comes closer than `clearance_mm` to the part, the table or a fixture (and of those,
    to the table, to a fixture), those touching (0 mm), and the deepest penetration.
    `cloud`: a bounded sample of the valid points with their errors, for the maps;
    `coverage_map`: the surface samples and their `SurfaceState`, for the in-spec map.
    """

    part: str
    planner: str
    sensor: str
    profiles: int
    points_per_profile: int
    valid_fraction: float
    in_range_fraction: float
    distance_error_mean_abs_mm: float
    distance_error_rms_mm: float
    distance_error_p95_abs_mm: float
    distance_error_mean_mm: float
    profile_distance_error_mean_abs_mm: float
    orientation_error_mean_deg: float
    orientation_error_p95_deg: float
    spacing_mean_mm: float
    spacing_cv: float
    spacing_max_gap_mm: float
    backward_steps: int
    spacing_pairs: int
    pairs_without_overlap: int
    coverage_fraction: float
    coverage_radius_mm: float
    surface: str
    visible_area_mm2: float
    in_spec_coverage: float
    in_spec_radius_mm: float
    in_spec_cell_mm: float
    tolerance_mm: float
    tolerance_deg: float
    path_length_mm: float
    scan_length_mm: float
    move_length_mm: float
    cycle_time_s: float
    scan_time_s: float
    move_time_s: float
    plan_time_s: float
    eval_time_s: float
    reward_mean: float
    r_d_mean: float
    r_alpha_mean: float
    r_delta_s_mean: float
    collisions_count: int
    collisions_touching: int
    collisions_table: int
    collisions_fixtures: int
    worst_penetration_mm: float
    clearance_mm: float
    visibility_ceiling: float | None = None
    cloud: PointCloud | None = field(default=None, repr=False, compare=False)
    coverage_map: CoverageMap | None = field(default=None, repr=False, compare=False)
    cycle: CycleTime | None = field(default=None, repr=False, compare=False)
    # The defect the plan would find, predicted from its own scan (`detectability.evaluate_
    # detectable`): type, a50/a90 (mm, None where too little is seen) and its map (the
    # sampled surface points (k, 3), the smallest depth found at 90 % there (k,), inf: none).
    detectable: dict[str, Any] | None = None
    detectable_map: tuple[np.ndarray, np.ndarray] | None = field(
        default=None, repr=False, compare=False
    )

    @property
    def in_spec_of_ceiling(self) -> float | None:
        """In-spec coverage as a share of the visibility ceiling (None if that is unmeasured
        or 0)."""
        if not self.visibility_ceiling:
            return None
        return self.in_spec_coverage / self.visibility_ceiling

    def to_json_dict(self) -> dict[str, Any]:
        """The SPEC §8 keys (and more): plain floats and ints, None where a number is not
        finite, so `json.dumps(..., allow_nan=False)` always succeeds."""
        return json_safe(
            {
                "part": self.part,
                "planner": self.planner,
                "sensor": self.sensor,
                "profiles": self.profiles,
                "points_per_profile": self.points_per_profile,
                "in_spec_coverage": self.in_spec_coverage,
                "visibility_ceiling": self.visibility_ceiling,
                "in_spec_of_ceiling": self.in_spec_of_ceiling,
                "visibility_ceiling_definition": VISIBILITY_CEILING_DEFINITION,
                "tolerance": {"mm": self.tolerance_mm, "deg": self.tolerance_deg},
                "in_spec_definition": IN_SPEC_COVERAGE_DEFINITION,
                "in_spec_radius_mm": self.in_spec_radius_mm,
                "in_spec_cell_mm": self.in_spec_cell_mm,
                "distance_error_mm": {
                    "mean_abs": self.distance_error_mean_abs_mm,
                    "rms": self.distance_error_rms_mm,
                    "p95_abs": self.distance_error_p95_abs_mm,
                    "mean": self.distance_error_mean_mm,
                    "profile_mean_abs": self.profile_distance_error_mean_abs_mm,
                },
                "orientation_error_deg": {
                    "mean": self.orientation_error_mean_deg,
                    "p95": self.orientation_error_p95_deg,
                },
                "in_range_fraction": self.in_range_fraction,
                "valid_fraction": self.valid_fraction,
                "coverage_fraction": self.coverage_fraction,
                "coverage_definition": COVERAGE_DEFINITION,
                "coverage_radius_mm": self.coverage_radius_mm,
                "surface": {"name": self.surface, "area_mm2": self.visible_area_mm2},
                "visible_area_mm2": self.visible_area_mm2,
                "spacing_mm": {
                    "mean": self.spacing_mean_mm,
                    "cv": self.spacing_cv,
                    "max_gap": self.spacing_max_gap_mm,
                    "backward_steps": self.backward_steps,
                    "pairs": self.spacing_pairs,
                    "pairs_without_overlap": self.pairs_without_overlap,
                },
                "path_length_mm": self.path_length_mm,
                "scan_length_mm": self.scan_length_mm,
                "move_length_mm": self.move_length_mm,
                "cycle_time_s": self.cycle_time_s,
                "scan_time_s": self.scan_time_s,
                "move_time_s": self.move_time_s,
                "cycle_time": self.cycle.to_json_dict() if self.cycle else None,
                "plan_time_s": self.plan_time_s,
                "eval_time_s": self.eval_time_s,
                "reward": {
                    "mean": self.reward_mean,
                    "r_d": self.r_d_mean,
                    "r_alpha": self.r_alpha_mean,
                    "r_delta_s": self.r_delta_s_mean,
                },
                "collisions": {
                    "count": self.collisions_count,
                    "count_touching": self.collisions_touching,
                    "table": self.collisions_table,
                    "fixtures": self.collisions_fixtures,
                    "worst_penetration_mm": self.worst_penetration_mm,
                    "clearance_mm": self.clearance_mm,
                },
                "detectable": self.detectable,
            }
        )
