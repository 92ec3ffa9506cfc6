"""Scan-quality metrics of a trajectory (SPEC §7): simulate its scan, summarize the errors.

`evaluate` measures every scanning pose in chunks and streams them through small
accumulators — per-point errors (running sums, fixed-bin histograms for the percentiles),
spacing (per-profile D, α, Δs), coverage (plain and in-spec, on area samples of the surface)
and a bounded sample of points for the maps — so a full 4096-column scan of the door fits in
memory. D, α, Δs, the in-spec test and the rewards come from `quantities` and `reward`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np

from scanplan.cloud import PointCloud
from scanplan.collision import checker_for
from scanplan.part import Part
from scanplan.quantities import (
    ScanSpec,
    advance,
    in_spec,
    mean_distance,
    point_orientation_error,
    signed_alpha,
)
from scanplan.reward import reward_terms
from scanplan.sensor import LineProfilometer, PointStatus, Scan, SensorSpec
from scanplan.trajectory import Trajectory

COVERAGE_MAX_SLOPE_DEG = 80.0
COVERAGE_DEFINITION = (
    "fraction of the part's upward-visible area sampled by valid points: the surface is "
    "sampled uniformly by area (seeded); a sample is upward-visible if its face is within "
    f"{COVERAGE_MAX_SLOPE_DEG:.0f} deg of horizontal and a vertical ray from it escapes the part "
    "(what a top-down raster can possibly see); it is covered if a valid measured point lies "
    "within `coverage_radius_mm` of it (about the spacing of the measured columns)"
)
IN_SPEC_COVERAGE_DEFINITION = (
    "fraction of the same upward-visible area samples that have, within `in_spec_radius_mm`, "
    "a measured point that is valid, has |z_s - W_d| <= tol_d and alpha_i <= tol_alpha "
    "(`tolerance`), and lies where the real scan samples the surface at least once per "
    "(2 delta_s_opt)^2: on the surface, at the point's distance, the real sensor's spacing is "
    "<= 2 delta_s_opt both along the pass (the column's displacement to its neighbouring "
    "profiles of the pass, the larger of the two) and across it (the real sensor's column "
    "pitch, not the evaluation's sub-sampled fan). The radius is half the diagonal of a cell "
    "2 delta_s_opt long and one evaluated column pitch wide (at the far tolerance depth and "
    "tilt), so a sub-sampled fan still reaches every sample between its columns, while "
    "profiles sparser than 2 delta_s_opt fail however wide the radius"
)
CYCLE_TIME_ASSUMPTIONS = (
    "one profile per station at the sensor's profile rate (scan speed = rate x spacing); "
    "non-scanning moves at the travel speed along straight segments; no acceleration or "
    "settling time"
)
# Histogram bins for the percentiles: fine enough to be exact to well below the noise.
_DIST_BIN_MM = 1e-3
_ORI_BIN_DEG = 1e-3


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
    least one point per `in_spec_cell_mm`² (2·Δs_opt).
    Cycle time: see `CYCLE_TIME_ASSUMPTIONS`; split into scanning (profiles at the profile
    rate) and moving (the rest of the path at the travel speed).
    Collisions (every pose, scanning or not; `collision.CollisionChecker`): poses whose sensor
    body comes closer to the part than `clearance_mm`, those touching it (0 mm), and the
    deepest penetration.
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
    profile_rate_hz: float
    travel_speed_mm_s: float
    plan_time_s: float
    eval_time_s: float
    reward_mean: float
    r_d_mean: float
    r_alpha_mean: float
    r_delta_s_mean: float
    collisions_count: int
    collisions_touching: int
    worst_penetration_mm: float
    clearance_mm: float
    cloud: PointCloud | None = field(default=None, repr=False, compare=False)
    coverage_map: CoverageMap | None = field(default=None, repr=False, compare=False)

    def to_json_dict(self) -> dict[str, Any]:
        """The SPEC §8 keys (and more): plain floats and ints, None where a number is not
        finite, so `json.dumps(..., allow_nan=False)` always succeeds."""
        return _finite_or_none(
            {
                "part": self.part,
                "planner": self.planner,
                "sensor": self.sensor,
                "profiles": self.profiles,
                "points_per_profile": self.points_per_profile,
                "in_spec_coverage": self.in_spec_coverage,
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
                "cycle_time_assumptions": {
                    "profile_rate_hz": self.profile_rate_hz,
                    "travel_speed_mm_s": self.travel_speed_mm_s,
                    "model": CYCLE_TIME_ASSUMPTIONS,
                },
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
                    "worst_penetration_mm": self.worst_penetration_mm,
                    "clearance_mm": self.clearance_mm,
                },
            }
        )


def _finite_or_none(value: Any) -> Any:
    """Plain Python numbers in nested dicts and lists, NaN and ±inf as None."""
    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite_or_none(v) for v in value]
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    return value


# ---- coverage -----------------------------------------------------------------------------


@dataclass(frozen=True)
class VisibleSurface:
    """Area-uniform samples of the visible surface to inspect. points: (k, 3); area_mm2:
    total; faces: (k,) the face each sample lies on."""

    points: np.ndarray
    area_mm2: float
    faces: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))


def _area_samples(
    part: Part, candidate: np.ndarray, spacing_mm: float, seed: int
) -> tuple[np.ndarray, np.ndarray, float]:
    """About one point per spacing² of the `candidate` faces' area (20 000..400 000),
    uniform by area, seeded: (points (k, 3), faces (k,), candidate area)."""
    area = np.asarray(part.mesh.area_faces)
    cand_area = float(area[candidate].sum())
    if cand_area <= 0:
        return np.zeros((0, 3)), np.zeros(0, np.int64), 0.0
    count = int(np.clip(cand_area / spacing_mm**2, 20_000, 400_000))
    rng = np.random.default_rng(seed)
    idx = np.flatnonzero(candidate)
    faces = rng.choice(idx, size=count, p=area[idx] / cand_area)
    r1, r2 = rng.random(count), rng.random(count)
    flip = r1 + r2 > 1  # fold the unit square onto the triangle
    r1, r2 = np.where(flip, 1 - r1, r1), np.where(flip, 1 - r2, r2)
    tri = part.ray_engine.triangles[faces]
    points = (
        tri[:, 0] + r1[:, None] * (tri[:, 1] - tri[:, 0]) + r2[:, None] * (tri[:, 2] - tri[:, 0])
    )
    return points, faces, cand_area


def coverage_spacing_mm(sensor: SensorSpec) -> float:
    """The spacing of the coverage samples `evaluate` draws for a fan of this sensor."""
    lateral_spacing = sensor.line_width_mm / max(sensor.points_per_profile - 1, 1)
    return max(2.0, 1.2 * lateral_spacing)


def hemisphere_visible_samples(
    part: Part, spacing_mm: float, seed: int = 0, directions: np.ndarray | None = None
) -> VisibleSurface:
    """The surface a sensor can see from the upper hemisphere (`--views auto`): samples of
    the faces to inspect (any slope) kept if, along at least one of `directions` (default
    `views.hemisphere_directions`, 28 directions up to 75° from +Z), the face is within
    COVERAGE_MAX_SLOPE_DEG of facing it (either winding) and a ray from it escapes the part."""
    from scanplan.views import hemisphere_directions

    dirs = hemisphere_directions() if directions is None else np.asarray(directions, float)
    points, faces, cand_area = _area_samples(part, part.inspect_mask, spacing_mm, seed)
    n = part.ray_engine.face_normals[faces]
    facing_cos = math.cos(math.radians(COVERAGE_MAX_SLOPE_DEG))
    visible = np.zeros(len(points), bool)
    for d in dirs:
        cos = n @ d
        todo = np.flatnonzero(~visible & (np.abs(cos) > facing_cos))
        if len(todo) == 0:
            continue
        start = points[todo] + np.sign(cos[todo])[:, None] * n[todo] * 0.05
        ray = np.broadcast_to(d, start.shape)
        visible[todo] = ~part.ray_engine.occluded(start, ray, np.full(len(todo), 1e6))
    frac = float(visible.mean()) if len(visible) else 0.0
    return VisibleSurface(points[visible], cand_area * frac, faces[visible])


def upward_visible_samples(part: Part, spacing_mm: float, seed: int = 0) -> VisibleSurface:
    """Sample faces within COVERAGE_MAX_SLOPE_DEG of horizontal (either winding) at about one
    point per spacing² of area; keep the samples from which a vertical ray escapes. Only the
    part's faces to inspect (its region of interest) are sampled; the whole part occludes."""
    normals = part.ray_engine.face_normals
    steep_cos = math.cos(math.radians(COVERAGE_MAX_SLOPE_DEG))
    candidate = (np.abs(normals[:, 2]) > steep_cos) & part.inspect_mask
    points, faces, cand_area = _area_samples(part, candidate, spacing_mm, seed)
    if cand_area <= 0:
        return VisibleSurface(np.zeros((0, 3)), 0.0)
    count = len(points)
    up_normal = normals[faces] * np.sign(normals[faces, 2:3])
    start = points + up_normal * 0.05  # off the face, above float32 error at part scale
    up = np.tile([0.0, 0.0, 1.0], (count, 1))
    blocked = part.ray_engine.occluded(start, up, np.full(count, 1e6))
    visible = ~blocked
    return VisibleSurface(points[visible], cand_area * float(visible.mean()), faces[visible])


def real_column_pitch(scan: Scan, sensor: SensorSpec, cols: slice = slice(None)) -> np.ndarray:
    """The real sensor's spacing between adjacent pixel columns on the surface, where each
    point lies, mm: (m, n) for the columns `cols` of the scan; NaN where the point is invalid.

    The columns are evenly spaced in x at z = W_d (pitch δ = line width / (N − 1)), so at depth
    z a column step sweeps the arc δ·z²/(ρ·W_d) across the beam, ρ the point's distance from
    the emitter; on the surface that arc grows by 1/cos β, β the angle between the beam and
    the surface's normal within the laser plane."""
    delta = sensor.line_width_mm / max(sensor.points_per_profile - 1, 1)
    points = scan.points_part[:, cols]
    normals = scan.normals_part[:, cols]
    ray = points - scan.poses[:, None, :3, 3]
    rho = np.linalg.norm(ray, axis=-1)
    y_s = scan.poses[:, None, :3, 1]
    n_plane = normals - np.sum(normals * y_s, axis=-1, keepdims=True) * y_s
    cos_beta = np.abs(np.sum(n_plane * ray, axis=-1)) / np.maximum(
        np.linalg.norm(n_plane, axis=-1) * rho, 1e-12
    )
    z = scan.z_sensor[:, cols]
    with np.errstate(divide="ignore", invalid="ignore"):
        return delta * z**2 / (rho * sensor.working_distance_mm * cos_beta)


# ---- the accumulators `evaluate` streams the chunks through ---------------------------------


def _percentile_from_hist(hist: np.ndarray, bin_width: float, q: float) -> float:
    total = hist.sum()
    if total == 0:
        return 0.0
    k = int(np.searchsorted(np.cumsum(hist), q * total))
    return (k + 0.5) * bin_width


class _PointErrors:
    """Per-point distance and orientation errors: counts, running sums, fixed-bin histograms."""

    def __init__(self, working_distance_mm: float, z_range_mm: float) -> None:
        self.wd = working_distance_mm
        self.n_points = self.n_valid = self.n_hit = self.n_in_range = 0
        self.sum_abs = self.sum_sq = self.sum_signed = self.sum_ori = 0.0
        self.dist_hist = np.zeros(int(math.ceil(z_range_mm / 2 / _DIST_BIN_MM)) + 2, np.int64)
        self.ori_hist = np.zeros(int(math.ceil(90.0 / _ORI_BIN_DEG)) + 2, np.int64)

    def add(self, scan: Scan, ori_rad: np.ndarray) -> None:
        valid = scan.valid
        hit = scan.face >= 0
        self.n_points += valid.size
        self.n_valid += int(valid.sum())
        self.n_hit += int(hit.sum())
        self.n_in_range += int((hit & (scan.status != PointStatus.OUT_OF_RANGE)).sum())
        err = scan.z_sensor[valid] - self.wd
        abs_err = np.abs(err)
        self.sum_abs += float(abs_err.sum())
        self.sum_sq += float((err**2).sum())
        self.sum_signed += float(err.sum())
        self.dist_hist += self._bincount(abs_err / _DIST_BIN_MM, self.dist_hist)
        ori = np.degrees(ori_rad[valid])
        self.sum_ori += float(ori.sum())
        self.ori_hist += self._bincount(ori / _ORI_BIN_DEG, self.ori_hist)

    @staticmethod
    def _bincount(bins: np.ndarray, hist: np.ndarray) -> np.ndarray:
        return np.bincount(np.minimum(bins.astype(np.int64), len(hist) - 1), minlength=len(hist))

    def summary(self) -> dict[str, Any]:
        n = self.n_valid
        return {
            "valid_fraction": n / self.n_points,
            "in_range_fraction": self.n_in_range / self.n_hit if self.n_hit else 0.0,
            "distance_error_mean_abs_mm": self.sum_abs / n,
            "distance_error_rms_mm": math.sqrt(self.sum_sq / n),
            "distance_error_p95_abs_mm": _percentile_from_hist(self.dist_hist, _DIST_BIN_MM, 0.95),
            "distance_error_mean_mm": self.sum_signed / n,
            "orientation_error_mean_deg": self.sum_ori / n,
            "orientation_error_p95_deg": _percentile_from_hist(self.ori_hist, _ORI_BIN_DEG, 0.95),
        }


def _mean_or_zero(a: np.ndarray) -> float:
    return float(a.mean()) if len(a) else 0.0


class _Spacing:
    """Per-profile D, α and Δs (to the previous profile, carried across chunks); at the end,
    the spacing statistics and the reward terms of the steps (a profile and its predecessor
    in the same pass)."""

    def __init__(self, u_dir: np.ndarray, has_prev: np.ndarray) -> None:
        m = len(u_dir)
        self.u_dir, self.has_prev = u_dir, has_prev
        self.d_prof = np.full(m, np.nan)
        self.a_prof = np.full(m, np.nan)
        self.ds_prof = np.full(m, np.nan)
        self._prev: tuple[np.ndarray, np.ndarray] | None = None

    def add(self, lo: int, scan: Scan) -> None:
        hi = lo + len(scan)
        valid, pts = scan.valid, scan.points_part
        self.d_prof[lo:hi] = mean_distance(scan.z_sensor, valid)
        self.a_prof[lo:hi] = signed_alpha(scan.normals_part, valid, scan.poses)
        if self._prev is not None:
            pts_prev = np.concatenate([self._prev[0][None], pts[:-1]])
            val_prev = np.concatenate([self._prev[1][None], valid[:-1]])
        else:
            pts_prev = np.concatenate([pts[:1], pts[:-1]])
            val_prev = np.concatenate([np.zeros_like(valid[:1]), valid[:-1]])
        self.ds_prof[lo:hi] = advance(pts_prev, val_prev, pts, valid, self.u_dir[lo:hi])
        self._prev = (pts[-1], valid[-1])

    def summary(self, working_distance_mm: float, scan_spec: ScanSpec) -> dict[str, Any]:
        ds_prof = self.ds_prof.copy()
        ds_prof[~self.has_prev] = np.nan
        steps = np.flatnonzero(self.has_prev)
        ds_ok = ds_prof[steps][np.isfinite(ds_prof[steps])]
        terms = reward_terms(self.d_prof[steps], self.a_prof[steps], ds_prof[steps], scan_spec)
        d_ok = self.d_prof[np.isfinite(self.d_prof)]
        spacing_mean = float(ds_ok.mean()) if len(ds_ok) else 0.0
        return {
            "profile_distance_error_mean_abs_mm": _mean_or_zero(np.abs(d_ok - working_distance_mm)),
            "spacing_mean_mm": spacing_mean,
            "spacing_cv": (
                float(ds_ok.std() / abs(spacing_mean)) if len(ds_ok) and spacing_mean else 0.0
            ),
            "spacing_max_gap_mm": float(ds_ok.max()) if len(ds_ok) else 0.0,
            "backward_steps": int((ds_ok < 0).sum()),
            "spacing_pairs": len(ds_ok),
            "pairs_without_overlap": int(len(steps) - len(ds_ok)),
            "reward_mean": _mean_or_zero(terms["reward"]),
            "r_d_mean": _mean_or_zero(terms["r_d"]),
            "r_alpha_mean": _mean_or_zero(terms["r_alpha"]),
            "r_delta_s_mean": _mean_or_zero(terms["r_delta_s"]),
        }


class _Coverage:
    """Plain and in-spec coverage of the surface samples (see the two definitions).

    Plain: a sample is covered if a valid point lies within `cover_radius`. In-spec: a point
    qualifies if it passes `quantities.in_spec` and the real scan is dense enough where it
    lies (across: `real_column_pitch`; along: the column's displacement to its neighbouring
    profiles of the pass); a sample is in spec if a qualifying point lies within
    `in_spec_radius`. The gap to the next profile is only known once the next profile is
    measured, so the last profile of each chunk waits for the next chunk.
    """

    def __init__(
        self,
        surface: VisibleSurface,
        scan_spec: ScanSpec,
        col_stride: int,
        cover_radius: float,
        in_spec_radius: float,
    ) -> None:
        self.surface, self.spec = surface, scan_spec
        self.cols = slice(None, None, col_stride)
        self.cover_radius, self.in_spec_radius = cover_radius, in_spec_radius
        self.limit_mm = 2.0 * scan_spec.delta_s_opt_mm
        k = len(surface.points)
        self.covered = np.zeros(k, bool)
        self.in_spec = np.zeros(k, bool)
        self.tree = None
        if k:
            from scipy.spatial import cKDTree

            self.tree = cKDTree(surface.points)
            # Enough neighbours that every sample within the radius of a point is returned.
            per_mm2 = k / max(surface.area_mm2, 1e-9)
            expected = per_mm2 * math.pi * in_spec_radius**2
            self.k_in_spec = int(np.clip(math.ceil(2 * expected + 4), 4, 64))
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # previous profile's columns
        # The held-back last profile: points, qualifies-but-for-the-along-gap, gap to previous.
        self._pending: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def add(self, scan: Scan, ori_rad: np.ndarray, has_prev: np.ndarray) -> None:
        if self.tree is None:
            return
        c = self.cols
        valid = scan.valid[:, c]
        pts = scan.points_part[:, c]
        near = pts[valid]
        if len(near):
            # k nearest: a sample with a small Voronoi cell is still marked.
            dist, which = self.tree.query(
                near, k=8, distance_upper_bound=self.cover_radius, workers=-1
            )
            self.covered[which[np.isfinite(dist)]] = True

        ok = in_spec(scan.z_sensor[:, c], ori_rad[:, c], valid, self.spec)
        ok &= real_column_pitch(scan, self.spec.sensor, c) <= self.limit_mm
        if self._last is not None:
            pts_prev = np.concatenate([self._last[0][None], pts[:-1]])
            val_prev = np.concatenate([self._last[1][None], valid[:-1]])
        else:
            pts_prev = np.concatenate([pts[:1], pts[:-1]])
            val_prev = np.concatenate([np.zeros_like(valid[:1]), valid[:-1]])
        self._last = (pts[-1], valid[-1])
        both = valid & val_prev & has_prev[:, None]
        gap_prev = np.where(both, np.linalg.norm(pts - pts_prev, axis=-1), np.nan)
        if self._pending is not None:
            pts = np.concatenate([self._pending[0][None], pts])
            ok = np.concatenate([self._pending[1][None], ok])
            gap_prev = np.concatenate([self._pending[2][None], gap_prev])
        gap_next = np.full_like(gap_prev, np.nan)
        gap_next[:-1] = gap_prev[1:]
        self._pending = (pts[-1], ok[-1], gap_prev[-1])
        self._mark_in_spec(pts[:-1], ok[:-1], gap_prev[:-1], gap_next[:-1])

    def _mark_in_spec(
        self, pts: np.ndarray, ok: np.ndarray, gap_prev: np.ndarray, gap_next: np.ndarray
    ) -> None:
        # The larger of the two gaps, or the one there is; none (an isolated profile) fails.
        along = np.fmax(gap_prev, gap_next)
        with np.errstate(invalid="ignore"):
            good = pts[ok & (along <= self.limit_mm)]
        if len(good) and self.tree is not None:
            dist, which = self.tree.query(
                good, k=self.k_in_spec, distance_upper_bound=self.in_spec_radius, workers=-1
            )
            self.in_spec[which[np.isfinite(dist)]] = True

    def finish(self) -> tuple[float, float, CoverageMap]:
        """(coverage fraction, in-spec fraction, the map)."""
        if self._pending is not None:
            p, ok, gap = self._pending
            self._mark_in_spec(p[None], ok[None], gap[None], np.full_like(gap[None], np.nan))
            self._pending = None
        state = np.where(
            self.in_spec,
            SurfaceState.IN_SPEC,
            np.where(self.covered, SurfaceState.OUT_OF_SPEC, SurfaceState.UNSEEN),
        ).astype(np.int8)
        coverage_map = CoverageMap(self.surface.points, state)
        covered = float(self.covered.mean()) if len(self.covered) else 0.0
        return covered, coverage_map.fraction(SurfaceState.IN_SPEC), coverage_map


class _CloudSample:
    """A bounded, seeded random sample of the valid points with their errors, for the maps."""

    def __init__(self, n_points: int, max_points: int, seed: int) -> None:
        self.stride = max(1.0, n_points / (2 * max_points))
        self.rng = np.random.default_rng(seed)
        self.parts: dict[str, list[np.ndarray]] = {k: [] for k in PointCloud.__dataclass_fields__}

    def add(self, lo: int, scan: Scan, ori_rad: np.ndarray, swath: np.ndarray, wd: float) -> None:
        rows, cols = np.nonzero(scan.valid)
        # Seeded random pick: a stride over row-major points would draw moire on the maps.
        pick = np.flatnonzero(self.rng.random(len(rows)) * self.stride < 1.0)
        r, c = rows[pick], cols[pick]
        self.parts["points_part"].append(scan.points_part[r, c])
        self.parts["distance_error_mm"].append(scan.z_sensor[r, c] - wd)
        self.parts["orientation_error_rad"].append(ori_rad[r, c])
        self.parts["profile"].append(lo + r)
        self.parts["swath"].append(swath[r])

    def cloud(self) -> PointCloud:
        return PointCloud(**{k: np.concatenate(v) for k, v in self.parts.items()})


# ---- evaluation ---------------------------------------------------------------------------


def _path_summary(traj: Trajectory, profiles: int, scan_spec: ScanSpec) -> dict[str, Any]:
    scan_len = float(
        np.linalg.norm(np.diff(traj.positions_mm, axis=0), axis=1)[
            traj.scanning[1:] & traj.scanning[:-1] & (traj.swath[1:] == traj.swath[:-1])
        ].sum()
    )
    path_len = traj.path_length_mm()
    scan_time = profiles / scan_spec.profile_rate_hz
    move_time = (path_len - scan_len) / scan_spec.travel_speed_mm_s
    return {
        "path_length_mm": path_len,
        "scan_length_mm": scan_len,
        "move_length_mm": path_len - scan_len,
        "cycle_time_s": scan_time + move_time,
        "scan_time_s": scan_time,
        "move_time_s": move_time,
        "profile_rate_hz": scan_spec.profile_rate_hz,
        "travel_speed_mm_s": scan_spec.travel_speed_mm_s,
        "plan_time_s": float(traj.plan_time_s),
    }


def in_spec_radius_mm(scan_spec: ScanSpec, evaluated_pitch_mm: float) -> float:
    """Search radius of the in-spec coverage: half the diagonal of a cell 2·Δs_opt long and
    one evaluated column pitch wide, that pitch taken at the far end of the distance
    tolerance and at the angle tolerance (capped at 60°) — the farthest a sample between two
    qualifying points can be from both."""
    tilt = min(scan_spec.tol_angle_rad, math.radians(60.0))
    far = 1.0 + scan_spec.tolerance_mm / scan_spec.working_distance_mm
    across = evaluated_pitch_mm * far / math.cos(tilt)
    return 0.5 * math.hypot(2.0 * scan_spec.delta_s_opt_mm, across)


def evaluate(
    part: Part,
    scan_spec: ScanSpec,
    traj: Trajectory,
    seed: int = 0,
    points_per_profile: int | None = None,
    chunk_poses: int = 256,
    max_map_points: int = 200_000,
    progress: Callable[[int, int], None] | None = None,
    visible: str = "auto",
) -> Metrics:
    """Simulate the scan of `traj` and summarize it (SPEC §7).

    points_per_profile: sub-sample the fan for a faster evaluation (same line width); the
    in-spec density rule still judges the real sensor's columns.
    progress(done, total): called after each chunk of scanning poses (a caller's progress bar).
    visible: the surface to inspect — 'top' the upward-visible surface
    (`upward_visible_samples`), 'hemisphere' what a sensor sees from the upper hemisphere
    (`hemisphere_visible_samples`), 'auto' the latter for a trajectory of several views
    (`meta["views"]`), else the former. Both keep to the part's region of interest.
    Raises ValueError if no scanning pose returns a valid point.
    """
    start_time = time.perf_counter()
    sensor = scan_spec.sensor
    spec = sensor.with_points(points_per_profile) if points_per_profile else sensor
    n_cols = spec.points_per_profile
    wd = spec.working_distance_mm
    if not traj.scanning.any():
        raise ValueError("trajectory has no scanning pose")
    scan_idx = np.flatnonzero(traj.scanning)
    poses = traj.poses[scan_idx]
    m = len(poses)
    swath = traj.swath[scan_idx]
    # A step: this profile and the previous pose of the trajectory, scanning in the same pass.
    has_prev = np.zeros(m, bool)
    has_prev[1:] = (swath[1:] == swath[:-1]) & (np.diff(scan_idx) == 1)
    u_dir = poses[:, :3, 1].copy()
    u_dir[:, 2] = 0.0  # y_s projected on the horizontal is the pass direction u
    u_dir /= np.maximum(np.linalg.norm(u_dir, axis=1, keepdims=True), 1e-12)

    lateral_spacing = spec.line_width_mm / max(n_cols - 1, 1)
    cover_spacing = coverage_spacing_mm(spec)
    if visible == "auto":
        visible = "hemisphere" if len(traj.meta.get("views") or ()) > 1 else "top"
    if visible not in ("top", "hemisphere"):
        raise ValueError(f"unknown visible surface {visible!r}; use top, hemisphere or auto")
    sampler = upward_visible_samples if visible == "top" else hemisphere_visible_samples
    surface = sampler(part, cover_spacing, seed)
    # Decimate the points used for coverage to ~1/3 of the sample spacing: same answer, faster.
    col_stride = max(1, int(cover_spacing / 3 / lateral_spacing))
    # Wide enough that every sample between two measured lines has a point within reach.
    cover_radius = max(1.0, lateral_spacing * col_stride)
    in_spec_radius = in_spec_radius_mm(scan_spec, lateral_spacing * col_stride)

    errors = _PointErrors(wd, spec.z_range_mm)
    spacing = _Spacing(u_dir, has_prev)
    coverage = _Coverage(surface, scan_spec, col_stride, cover_radius, in_spec_radius)
    sample = _CloudSample(m * n_cols, max_map_points, seed)
    profiler = LineProfilometer(part, spec, seed=seed)
    for lo in range(0, m, chunk_poses):
        hi = min(m, lo + chunk_poses)
        scan = profiler.measure_many(poses[lo:hi])
        ori = point_orientation_error(scan.normals_part, scan.poses)
        errors.add(scan, ori)
        spacing.add(lo, scan)
        coverage.add(scan, ori, has_prev[lo:hi])
        sample.add(lo, scan, ori, swath[lo:hi], wd)
        if progress is not None:
            progress(hi, m)

    if errors.n_valid == 0:
        raise ValueError(
            f"no valid point: part {part.name} is outside the sensor's reach along this trajectory"
        )
    coverage_fraction, in_spec_fraction, coverage_map = coverage.finish()
    collisions = checker_for(part, sensor).check(traj.poses, scan_spec.clearance_mm)
    return Metrics(
        part=part.name,
        planner=traj.planner,
        sensor=spec.name,
        profiles=m,
        points_per_profile=n_cols,
        coverage_fraction=coverage_fraction,
        coverage_radius_mm=cover_radius,
        visible_area_mm2=surface.area_mm2,
        in_spec_coverage=in_spec_fraction,
        in_spec_radius_mm=in_spec_radius,
        in_spec_cell_mm=2.0 * scan_spec.delta_s_opt_mm,
        tolerance_mm=scan_spec.tolerance_mm,
        tolerance_deg=math.degrees(scan_spec.tol_angle_rad),
        eval_time_s=time.perf_counter() - start_time,
        cloud=sample.cloud(),
        coverage_map=coverage_map,
        collisions_count=int(collisions.colliding.sum()),
        collisions_touching=int(collisions.touching.sum()),
        worst_penetration_mm=collisions.worst_penetration_mm,
        clearance_mm=collisions.clearance_mm,
        **errors.summary(),
        **spacing.summary(wd, scan_spec),
        **_path_summary(traj, m, scan_spec),
    )
