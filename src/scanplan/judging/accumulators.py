"""The accumulators `evaluate` streams the simulated scan through, chunk by chunk: per-point
errors (running sums, fixed-bin histograms for the percentiles), per-profile spacing and
reward terms, plain and in-spec coverage of the surface samples, and a bounded sample of
points for the maps. D, α, Δs, the in-spec test and the rewards come from `quantities` and
`reward`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from scanplan.core.quantities import (
    ScanSpec,
    advance,
    beam_angle,
    cos_to_rays,
    dot_rows,
    in_spec,
    mean_distance,
    norm_rows,
    normal_in_laser_plane,
    signed_alpha,
)
from scanplan.core.reward import reward_terms
from scanplan.core.sensor_spec import SensorSpec
from scanplan.judging.chunks import (
    rows,
    samples_near,
    valid_cells,
    valid_index,
    valid_points,
    valid_points_tree,
)
from scanplan.judging.summary import CoverageMap, SurfaceState
from scanplan.sensor.cloud import PointCloud
from scanplan.sensor.profilometer import PointStatus, Scan
from scanplan.world.surface import VisibleSurface

# Histogram bins for the percentiles: fine enough to be exact to well below the noise.
_DIST_BIN_MM = 1e-3
_ORI_BIN_DEG = 1e-3


def real_column_pitch(scan: Scan, sensor: SensorSpec, cols: slice = slice(None)) -> np.ndarray:
    """The real sensor's spacing between adjacent pixel columns on the surface, where each
    point lies, mm: (m, n) for the columns `cols` of the scan; NaN where the point is invalid.

    The columns are evenly spaced in x at z = W_d (pitch δ = line width / (N − 1)), so at depth
    z a column step sweeps the arc δ·z²/(ρ·W_d) across the beam, ρ the point's distance from
    the emitter; on the surface that arc grows by 1/cos β, β the angle between the beam and
    the surface's normal within the laser plane."""
    delta = sensor.line_width_mm / max(sensor.points_per_profile - 1, 1)
    rays = sensor.ray_directions(scan.z_sensor.shape[1])[cols]  # the scan's fan: same line
    n_x, n_z = normal_in_laser_plane(scan.normals_part[:, cols], scan.poses[:, None])
    cos = cos_to_rays(n_x, n_z, rays)
    in_plane = np.sqrt(n_x * n_x + n_z * n_z)
    z = scan.z_sensor[:, cols]
    # On the flat (m, n) arrays: ρ = z / cos(ray to the axis), cos β = cos / |n in the plane|.
    with np.errstate(divide="ignore", invalid="ignore"):
        return delta * z * rays[:, 2] * in_plane / (sensor.working_distance_mm * cos)


def _percentile_from_hist(hist: np.ndarray, bin_width: float, q: float) -> float:
    total = hist.sum()
    if total == 0:
        return 0.0
    k = int(np.searchsorted(np.cumsum(hist), q * total))
    return (k + 0.5) * bin_width


class PointErrors:
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
        index = valid_index(scan, 1)  # flat takes, not boolean masks
        err = np.take(scan.z_sensor, index) - self.wd
        abs_err = np.abs(err)
        self.sum_abs += float(abs_err.sum())
        self.sum_sq += float((err**2).sum())
        self.sum_signed += float(err.sum())
        self.dist_hist += self._bincount(abs_err / _DIST_BIN_MM, self.dist_hist)
        ori = np.degrees(np.take(ori_rad, index))
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


class Spacing:
    """Per-profile D, α and Δs (to the previous profile, carried across chunks); at the end,
    the spacing statistics and the reward terms of the steps (a profile and its predecessor
    in the same pass). full_beam_angle: α is the whole angle between beam and mean normal
    (the reward of env v1, what a rolling planner is charged), else the pitch error (v0)."""

    def __init__(self, u_dir: np.ndarray, has_prev: np.ndarray, full_beam_angle: bool) -> None:
        m = len(u_dir)
        self.u_dir, self.has_prev = u_dir, has_prev
        self.orientation = beam_angle if full_beam_angle else signed_alpha
        self.d_prof = np.full(m, np.nan)
        self.a_prof = np.full(m, np.nan)
        self.ds_prof = np.full(m, np.nan)
        self._prev: tuple[np.ndarray, np.ndarray] | None = None

    def add(self, lo: int, scan: Scan) -> None:
        hi = lo + len(scan)
        valid, pts = scan.valid, scan.points_part
        self.d_prof[lo:hi] = mean_distance(scan.z_sensor, valid)
        self.a_prof[lo:hi] = self.orientation(scan.normals_part, valid, scan.poses)
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


# A point marks the samples within the in-spec radius whose outward normal lies within 45°
# of its own: across an edge or a thin sheet the samples are another side's. Without this,
# a 128-column fan read 0.91 on the NIST sheet metal part (above its 0.85 ceiling) where
# the full sensor reads 0.76.
SAME_SIDE_COS = math.cos(math.radians(45.0))


class Coverage:
    """Plain and in-spec coverage of the surface samples (see the two definitions).

    Plain: a sample is covered if a valid point lies within `cover_radius`. In-spec: a point
    qualifies if it passes `quantities.in_spec` and the real scan is dense enough where it
    lies (across: `real_column_pitch`; along: the column's displacement to its neighbouring
    profiles of the pass); a sample is in spec if a qualifying point lies within
    `in_spec_radius` on the sample's side (`SAME_SIDE_COS` between the point's normal and
    the sample's outward normal, `normals` (k, 3)). The gap to the next profile is only
    known once the next profile is measured, so the last profile of each chunk waits for
    the next chunk. plain=False: the in-spec set alone.
    """

    def __init__(
        self,
        surface: VisibleSurface,
        scan_spec: ScanSpec,
        col_stride: int,
        cover_radius: float,
        in_spec_radius: float,
        normals: np.ndarray,
        plain: bool = True,
    ) -> None:
        self.surface, self.spec = surface, scan_spec
        self.normals = normals
        self.col_stride = col_stride
        self.cols = slice(None, None, col_stride)
        self.cover_radius, self.in_spec_radius = cover_radius, in_spec_radius
        self.plain = plain
        self.limit_mm = 2.0 * scan_spec.delta_s_opt_mm
        k = len(surface.points)
        self.covered = np.zeros(k, bool)
        self.in_spec = np.zeros(k, bool)
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # previous profile's columns
        # The held-back last profile: points, qualifies-but-for-the-along-gap, gap to previous.
        self._pending: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None

    def add(self, scan: Scan, ori_rad: np.ndarray, has_prev: np.ndarray) -> None:
        if not len(self.surface.points):
            return
        c = self.cols
        valid = scan.valid[:, c]
        pts = scan.points_part[:, c]
        nrm = scan.normals_part[:, c]
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
        gap_prev = np.where(both, norm_rows(pts - pts_prev), np.nan)
        if self._pending is not None:  # the previous chunk's last profile: now its next gap
            self._mark_in_spec(*self._pending, gap_prev[0])
        self._pending = (pts[-1], ok[-1], gap_prev[-1], nrm[-1])
        gap_next = np.full_like(gap_prev, np.nan)
        gap_next[:-1] = gap_prev[1:]
        qualifies = self._qualifies(ok, gap_prev, gap_next)
        qualifies[-1] = False  # the last profile waits for its next gap
        stride = self.col_stride
        reach = max(self.cover_radius, self.in_spec_radius) if self.plain else self.in_spec_radius
        self._mark_chunk(
            valid_points(scan, stride),  # pts[valid], row by row
            rows(scan.normals_part.reshape(-1, 3), valid_index(scan, stride)),
            qualifies[valid],
            samples_near(scan, stride, self.surface, reach),
            lambda: valid_points_tree(scan, stride),
        )

    def _qualifies(self, ok: np.ndarray, gap_prev: np.ndarray, gap_next: np.ndarray) -> np.ndarray:
        """Points in spec whose profile lies close enough to its neighbours: the larger of
        the two gaps, or the one there is; none (an isolated profile) fails."""
        along = np.fmax(gap_prev, gap_next)
        with np.errstate(invalid="ignore"):
            return ok & (along <= self.limit_mm)

    def _mark_in_spec(
        self,
        pts: np.ndarray,
        ok: np.ndarray,
        gap_prev: np.ndarray,
        nrm: np.ndarray,
        gap_next: np.ndarray | float,
    ) -> None:
        """The held-back profile (n, 3) judged once its next gap is known (NaN: none)."""
        qualifies = self._qualifies(ok, gap_prev, np.broadcast_to(gap_next, gap_prev.shape))
        self._mark(self.in_spec, pts[qualifies], nrm[qualifies], self.in_spec_radius)

    def _mark_chunk(
        self,
        points: np.ndarray,
        normals: np.ndarray,
        qualifies: np.ndarray,
        near: np.ndarray,
        tree: Callable[[], cKDTree],
    ) -> None:
        """Cover the samples within the cover radius of the chunk's valid `points` (n, 3),
        and hold in spec those within the in-spec radius of a qualifying one on their side:
        one query of each open sample's nearest point in the chunk's tree, which the
        detectability survey shares (a second tree of the qualifying points alone cost
        about as much as the first). near: the samples that may lie within reach
        (`VisibleSurface.near`)."""
        if not len(points):
            return
        cover, held = self.cover_radius, self.in_spec_radius
        if 2 * np.count_nonzero(qualifies) < len(points):
            # Few qualify (a plan far off its stand-off): the nearest point would seldom be
            # one, so many samples would look among their neighbours; a tree of those few
            # costs less.
            if self.plain:
                open_ = near[~self.covered[near]]
                dist, _ = tree().query(rows(self.surface.points, open_), distance_upper_bound=cover)
                self.covered[open_[dist < cover]] = True
            if self.plain and held <= cover:  # within the in-spec radius of a point: covered
                near = near[self.covered[near]]
            few = np.flatnonzero(qualifies)
            self._mark(self.in_spec, rows(points, few), rows(normals, few), held, near)
            return
        reach = max(cover, held) if self.plain else held
        settled = self.in_spec[near]
        if self.plain and held > cover:  # in spec farther than a point covers: not settled
            settled &= self.covered[near]
        cand = near[~settled]
        if not len(cand):
            return
        samples = rows(self.surface.points, cand)
        dist, j = tree().query(samples, k=1, distance_upper_bound=reach)
        if self.plain:
            self.covered[cand[dist < cover]] = True
        near = np.flatnonzero(dist < held)
        j = j[near]
        same = dot_rows(rows(normals, j), rows(self.normals, cand[near])) >= SAME_SIDE_COS
        yes = qualifies[j] & same
        self.in_spec[cand[near[yes]]] = True
        # The nearest point does not qualify or lies on the other side (an edge, a thin
        # sheet): any other within the radius that does?
        self._mark_among(self.in_spec, cand[near[~yes]], points, normals, held, tree(), qualifies)

    def _mark_among(
        self,
        marked: np.ndarray,
        cand: np.ndarray,
        points: np.ndarray,
        normals: np.ndarray,
        radius: float,
        points_tree: cKDTree,
        usable: np.ndarray | None = None,
    ) -> None:
        """Mark those of the samples `cand` with a `usable` point (all: None) on their side
        within `radius`: their nearest points in `points_tree`, four times more each round
        while all of them lie within the radius."""
        samples = rows(self.surface.points, cand)
        rest = np.arange(len(cand))
        k = 8
        while len(rest):
            k = min(k, len(points))
            dist, j = points_tree.query(samples[rest], k=k, distance_upper_bound=radius)
            near = np.isfinite(dist)
            j = np.where(near, j, 0)
            cos = np.einsum("ijk,ik->ij", rows(normals, j), rows(self.normals, cand[rest]))
            good = near & (cos >= SAME_SIDE_COS)
            if usable is not None:
                good &= usable[j]
            hit = good.any(axis=1)
            marked[cand[rest[hit]]] = True
            # Still undecided: all k within the radius and none usable; look further.
            rest = rest[~hit & near[:, -1]] if k < len(points) else rest[:0]
            k *= 4

    def _mark(
        self,
        marked: np.ndarray,
        points: np.ndarray,
        normals: np.ndarray,
        radius: float,
        near: np.ndarray | None = None,
    ) -> None:
        """Mark in `marked` the samples within `radius` of one of `points` (n, 3) on the
        sample's side (the points' `normals`): from each open sample its nearest point.
        near: the samples that may lie within the radius (None: looked up)."""
        if not len(points):
            return
        cand = self.surface.near(points, radius) if near is None else near
        cand = cand[~marked[cand]]
        if not len(cand):
            return
        # Built per call and queried once: unbalanced, it builds faster.
        points_tree = cKDTree(points, balanced_tree=False, compact_nodes=False)
        dist, j = points_tree.query(
            rows(self.surface.points, cand), k=1, distance_upper_bound=radius
        )
        found = np.flatnonzero(np.isfinite(dist))
        same = dot_rows(rows(normals, j[found]), rows(self.normals, cand[found])) >= SAME_SIDE_COS
        marked[cand[found[same]]] = True
        other = found[~same]
        if len(other) and len(points) > 1:
            self._mark_among(marked, cand[other], points, normals, radius, points_tree)

    def finish(self) -> tuple[float, float, CoverageMap]:
        """(coverage fraction, in-spec fraction, the map)."""
        if self._pending is not None:
            self._mark_in_spec(*self._pending, np.nan)
            self._pending = None
        state = np.where(
            self.in_spec,
            SurfaceState.IN_SPEC,
            np.where(self.covered, SurfaceState.OUT_OF_SPEC, SurfaceState.UNSEEN),
        ).astype(np.int8)
        coverage_map = CoverageMap(self.surface.points, state)
        covered = float(self.covered.mean()) if len(self.covered) else 0.0
        return covered, coverage_map.fraction(SurfaceState.IN_SPEC), coverage_map


class CloudSample:
    """A bounded, seeded random sample of the valid points with their errors, for the maps."""

    def __init__(self, n_points: int, max_points: int, seed: int) -> None:
        self.stride = max(1.0, n_points / (2 * max_points))
        self.rng = np.random.default_rng(seed)
        self.parts: dict[str, list[np.ndarray]] = {k: [] for k in PointCloud.__dataclass_fields__}

    def add(self, lo: int, scan: Scan, ori_rad: np.ndarray, swath: np.ndarray, wd: float) -> None:
        index = valid_index(scan, 1)
        # Seeded random pick: a stride over row-major points would draw moire on the maps.
        pick = np.flatnonzero(self.rng.random(len(index)) * self.stride < 1.0)
        at, r = index[pick], valid_cells(scan, 1)[0][pick]
        self.parts["points_part"].append(rows(scan.points_part.reshape(-1, 3), at))
        self.parts["distance_error_mm"].append(np.take(scan.z_sensor, at) - wd)
        self.parts["orientation_error_rad"].append(np.take(ori_rad, at))
        self.parts["profile"].append(lo + r)
        self.parts["swath"].append(swath[r])

    def cloud(self) -> PointCloud:
        return PointCloud(**{k: np.concatenate(v) for k, v in self.parts.items()})
