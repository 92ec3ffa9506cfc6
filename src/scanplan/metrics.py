"""Scan-quality metrics of a trajectory (SPEC §7): simulate its scan, summarize the errors.

`evaluate` measures every scanning pose in chunks and keeps only running sums, fixed-bin
histograms (for the percentiles) and a bounded sample of points for the maps, so a full
4096-column scan of the door fits in memory. D, α, Δs and the rewards come from
`quantities` and `reward`, the same functions as the environment's.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from scanplan.cloud import PointCloud
from scanplan.part import Part
from scanplan.quantities import (
    ScanSpec,
    advance,
    mean_distance,
    point_orientation_error,
    signed_alpha,
)
from scanplan.reward import reward_terms
from scanplan.sensor import LineProfilometer, PointStatus
from scanplan.trajectory import Trajectory

COVERAGE_MAX_SLOPE_DEG = 80.0
COVERAGE_DEFINITION = (
    "fraction of the part's upward-visible area sampled by valid points: the surface is "
    "sampled uniformly by area (seeded); a sample is upward-visible if its face is within "
    f"{COVERAGE_MAX_SLOPE_DEG:.0f} deg of horizontal and a vertical ray from it escapes the part "
    "(what a top-down raster can possibly see); it is covered if a valid measured point lies "
    "within `coverage_radius_mm` of it (about the spacing of the measured columns)"
)
CYCLE_TIME_ASSUMPTIONS = (
    "one profile per station at the sensor's profile rate (scan speed = rate x spacing); "
    "non-scanning moves at the travel speed along straight segments; no acceleration or "
    "settling time"
)
# Histogram bins for the percentiles: fine enough to be exact to well below the noise.
_DIST_BIN_MM = 1e-3
_ORI_BIN_DEG = 1e-3


@dataclass(frozen=True)
class Metrics:
    """SPEC §7 summary of one trajectory's simulated scan. Lengths mm, angles degrees.

    Distance error per point: z_s − W_d; orientation error per point: α_i = acos(−z_s·n_i).
    Spacing: Δs (`quantities.advance`) between consecutive profiles of the same pass;
    `pairs_without_overlap` pairs share no valid column and are left out of the spacing stats.
    Rewards: per step (a profile and its predecessor in the pass), `reward.reward_terms`.
    Coverage: see `COVERAGE_DEFINITION`. Cycle time: see `CYCLE_TIME_ASSUMPTIONS`.
    `cloud`: a bounded sample of the valid points with their errors, for the maps.
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
    path_length_mm: float
    scan_length_mm: float
    cycle_time_s: float
    profile_rate_hz: float
    travel_speed_mm_s: float
    plan_time_s: float
    eval_time_s: float
    reward_mean: float
    r_d_mean: float
    r_alpha_mean: float
    r_delta_s_mean: float
    cloud: PointCloud | None = field(default=None, repr=False, compare=False)

    def to_json_dict(self) -> dict[str, Any]:
        """The SPEC §8 keys (and more), plain floats and ints, no NaN."""
        return {
            "part": self.part,
            "planner": self.planner,
            "sensor": self.sensor,
            "profiles": self.profiles,
            "points_per_profile": self.points_per_profile,
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
            "cycle_time_s": self.cycle_time_s,
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
        }


# ---- coverage -----------------------------------------------------------------------------


@dataclass(frozen=True)
class VisibleSurface:
    """Area-uniform samples of the upward-visible surface. points: (k, 3); area_mm2: total."""

    points: np.ndarray
    area_mm2: float


def upward_visible_samples(part: Part, spacing_mm: float, seed: int = 0) -> VisibleSurface:
    """Sample faces within COVERAGE_MAX_SLOPE_DEG of horizontal (either winding) at about one
    point per spacing² of area; keep the samples from which a vertical ray escapes."""
    mesh = part.mesh
    normals = part.ray_engine.face_normals
    area = np.asarray(mesh.area_faces)
    steep_cos = math.cos(math.radians(COVERAGE_MAX_SLOPE_DEG))
    candidate = np.abs(normals[:, 2]) > steep_cos
    cand_area = float(area[candidate].sum())
    if cand_area <= 0:
        return VisibleSurface(np.zeros((0, 3)), 0.0)
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
    up_normal = normals[faces] * np.sign(normals[faces, 2:3])
    start = points + up_normal * 0.05  # off the face, above float32 error at part scale
    up = np.tile([0.0, 0.0, 1.0], (count, 1))
    blocked = part.ray_engine.occluded(start, up, np.full(count, 1e6))
    visible = ~blocked
    return VisibleSurface(points[visible], cand_area * float(visible.mean()))


# ---- evaluation ---------------------------------------------------------------------------


def _percentile_from_hist(hist: np.ndarray, bin_width: float, q: float) -> float:
    total = hist.sum()
    if total == 0:
        return 0.0
    k = int(np.searchsorted(np.cumsum(hist), q * total))
    return (k + 0.5) * bin_width


def evaluate(
    part: Part,
    scan_spec: ScanSpec,
    traj: Trajectory,
    seed: int = 0,
    points_per_profile: int | None = None,
    profile_rate_hz: float = 200.0,
    travel_speed_mm_s: float = 250.0,
    chunk_poses: int = 256,
    max_map_points: int = 200_000,
) -> Metrics:
    """Simulate the scan of `traj` and summarize it (SPEC §7).

    points_per_profile: sub-sample the fan for a faster evaluation (same line width).
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
    cover_spacing = max(2.0, 1.2 * lateral_spacing)
    surface = upward_visible_samples(part, cover_spacing, seed)
    covered = np.zeros(len(surface.points), bool)
    tree = None
    if len(surface.points):
        from scipy.spatial import cKDTree

        tree = cKDTree(surface.points)
    # Decimate the points used for coverage to ~1/3 of the sample spacing: same answer, faster.
    col_stride = max(1, int(cover_spacing / 3 / lateral_spacing))
    # Wide enough that every sample between two measured lines has a point within reach.
    cover_radius = max(1.0, lateral_spacing * col_stride)

    profiler = LineProfilometer(part, spec, seed=seed)
    n_points = n_valid = n_hit = n_in_range = 0
    sum_abs = sum_sq = sum_signed = 0.0
    sum_ori = 0.0
    dist_hist = np.zeros(int(math.ceil(spec.z_range_mm / 2 / _DIST_BIN_MM)) + 2, np.int64)
    ori_hist = np.zeros(int(math.ceil(90.0 / _ORI_BIN_DEG)) + 2, np.int64)
    d_prof = np.full(m, np.nan)
    a_prof = np.full(m, np.nan)
    ds_prof = np.full(m, np.nan)
    map_stride = max(1.0, m * n_cols / (2 * max_map_points))
    map_rng = np.random.default_rng(seed)
    sample: dict[str, list[np.ndarray]] = {k: [] for k in PointCloud.__dataclass_fields__}
    prev_points: np.ndarray | None = None
    prev_valid: np.ndarray | None = None

    for lo in range(0, m, chunk_poses):
        hi = min(m, lo + chunk_poses)
        scan = profiler.measure_many(poses[lo:hi])
        valid = scan.valid
        hit = scan.face >= 0
        n_points += valid.size
        n_valid += int(valid.sum())
        n_hit += int(hit.sum())
        n_in_range += int((hit & (scan.status != PointStatus.OUT_OF_RANGE)).sum())

        err = scan.z_sensor[valid] - wd
        abs_err = np.abs(err)
        sum_abs += float(abs_err.sum())
        sum_sq += float((err**2).sum())
        sum_signed += float(err.sum())
        dist_hist += np.bincount(
            np.minimum((abs_err / _DIST_BIN_MM).astype(np.int64), len(dist_hist) - 1),
            minlength=len(dist_hist),
        )
        ori_all = point_orientation_error(scan.normals_part, scan.poses)
        ori = np.degrees(ori_all[valid])
        sum_ori += float(ori.sum())
        ori_hist += np.bincount(
            np.minimum((ori / _ORI_BIN_DEG).astype(np.int64), len(ori_hist) - 1),
            minlength=len(ori_hist),
        )

        d_prof[lo:hi] = mean_distance(scan.z_sensor, valid)
        a_prof[lo:hi] = signed_alpha(scan.normals_part, valid, scan.poses)
        # Δs against the previous profile, carried across chunk boundaries.
        pts = scan.points_part
        if prev_points is not None and prev_valid is not None:
            pts_prev = np.concatenate([prev_points[None], pts[:-1]])
            val_prev = np.concatenate([prev_valid[None], valid[:-1]])
        else:
            pts_prev = np.concatenate([pts[:1], pts[:-1]])
            val_prev = np.concatenate([np.zeros_like(valid[:1]), valid[:-1]])
        ds_prof[lo:hi] = advance(pts_prev, val_prev, pts, valid, u_dir[lo:hi])
        prev_points, prev_valid = pts[-1], valid[-1]

        if tree is not None:
            cols = valid[:, ::col_stride]
            near = pts[:, ::col_stride][cols]
            if len(near):
                # k nearest: a sample with a small Voronoi cell is still marked.
                dist, which = tree.query(near, k=8, distance_upper_bound=cover_radius, workers=-1)
                covered[which[np.isfinite(dist)]] = True

        rows, cols_idx = np.nonzero(valid)
        # Seeded random pick: a stride over row-major points would draw moire on the maps.
        pick = np.flatnonzero(map_rng.random(len(rows)) * map_stride < 1.0)
        r, c = rows[pick], cols_idx[pick]
        sample["points_part"].append(pts[r, c])
        sample["distance_error_mm"].append(scan.z_sensor[r, c] - wd)
        sample["orientation_error_rad"].append(ori_all[r, c])
        sample["profile"].append(lo + r)
        sample["swath"].append(swath[lo + r])

    if n_valid == 0:
        raise ValueError(
            f"no valid point: part {part.name} is outside the sensor's reach along this trajectory"
        )
    ds_prof[~has_prev] = np.nan
    steps = np.flatnonzero(has_prev)
    ds_ok = ds_prof[steps][np.isfinite(ds_prof[steps])]
    terms = reward_terms(d_prof[steps], a_prof[steps], ds_prof[steps], scan_spec)
    d_ok = d_prof[np.isfinite(d_prof)]

    spacing_mean = float(ds_ok.mean()) if len(ds_ok) else 0.0
    spacing_cv = float(ds_ok.std() / abs(spacing_mean)) if len(ds_ok) and spacing_mean else 0.0
    scan_len = float(
        np.linalg.norm(np.diff(traj.positions_mm, axis=0), axis=1)[
            traj.scanning[1:] & traj.scanning[:-1] & (traj.swath[1:] == traj.swath[:-1])
        ].sum()
    )
    path_len = traj.path_length_mm()
    cycle = m / scan_spec.profile_rate_hz + (path_len - scan_len) / scan_spec.travel_speed_mm_s
    cloud = PointCloud(**{k: np.concatenate(v) for k, v in sample.items()})

    def mean_or_zero(a: np.ndarray) -> float:
        return float(a.mean()) if len(a) else 0.0

    return Metrics(
        part=part.name,
        planner=traj.planner,
        sensor=spec.name,
        profiles=m,
        points_per_profile=n_cols,
        valid_fraction=n_valid / n_points,
        in_range_fraction=n_in_range / n_hit if n_hit else 0.0,
        distance_error_mean_abs_mm=sum_abs / n_valid,
        distance_error_rms_mm=math.sqrt(sum_sq / n_valid),
        distance_error_p95_abs_mm=_percentile_from_hist(dist_hist, _DIST_BIN_MM, 0.95),
        distance_error_mean_mm=sum_signed / n_valid,
        profile_distance_error_mean_abs_mm=mean_or_zero(np.abs(d_ok - wd)),
        orientation_error_mean_deg=sum_ori / n_valid,
        orientation_error_p95_deg=_percentile_from_hist(ori_hist, _ORI_BIN_DEG, 0.95),
        spacing_mean_mm=spacing_mean,
        spacing_cv=spacing_cv,
        spacing_max_gap_mm=float(ds_ok.max()) if len(ds_ok) else 0.0,
        backward_steps=int((ds_ok < 0).sum()),
        spacing_pairs=len(ds_ok),
        pairs_without_overlap=int(len(steps) - len(ds_ok)),
        coverage_fraction=float(covered.mean()) if len(covered) else 0.0,
        coverage_radius_mm=cover_radius,
        visible_area_mm2=surface.area_mm2,
        path_length_mm=path_len,
        scan_length_mm=scan_len,
        cycle_time_s=cycle,
        profile_rate_hz=scan_spec.profile_rate_hz,
        travel_speed_mm_s=scan_spec.travel_speed_mm_s,
        plan_time_s=float(traj.plan_time_s),
        eval_time_s=time.perf_counter() - start_time,
        reward_mean=mean_or_zero(terms["reward"]),
        r_d_mean=mean_or_zero(terms["r_d"]),
        r_alpha_mean=mean_or_zero(terms["r_alpha"]),
        r_delta_s_mean=mean_or_zero(terms["r_delta_s"]),
        cloud=cloud,
    )
