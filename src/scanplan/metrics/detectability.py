"""The smallest defect a plan would find where, predicted without injecting any: from the
scan of the defect-free part, at each sample of the surface to inspect, the points' density
(profile spacing x column pitch on the surface) and the noise σ along the normal there.

The model is the call rule of `detection` on a radial defect (dent, bump, pit) of depth a
and its width (`defects.shape`): the points flagged are those where the defect's depth
exceeds k·σ, inside a disc of radius r_k; the profiles cross it at the spacing, from an
offset uniform over one spacing, each with a chord of r_k's disc sampled at the column pitch.
A defect there is found when the flagged points reach the call's minimum: the share of
offsets for which they do is the probability of detection at that sample; its mean over the
surface is the predicted POD (defects land uniformly by area, as `defects.place` puts them).
A scratch (a groove of a half-width flagged over its length) is crossed by the profiles at
a direction averaged over.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from scanplan.defects import shape
from scanplan.metrics.detection import (
    Detector,
    FalseCalls,
    calls,
    cos_incidence,
    flagged,
    sigma_mm,
)
from scanplan.part import Part
from scanplan.profilometer import LineProfilometer
from scanplan.sensor import SensorSpec
from scanplan.surface import VisibleSurface

PREDICTED = ("dent", "bump", "pit", "scratch")
ANGLES = 8  # a scratch's directions to the scan averaged over
DENSITY_RADIUS_MM = 2.0
COLUMN_STRIDE = 4  # the density is counted on every 4th column (x 4)
OFFSETS = 16  # profile offsets averaged over, per sample
MAX_PREDICTED_SAMPLES = 20_000
WIDE_PROFILES = 4.0  # beyond this many profile spacings of radius, count by area


def flagged_radius(kind: str, q: np.ndarray) -> np.ndarray:
    """The radius over the defect's half-width (u) at which its depth profile falls to the
    share q of its depth (0 where q >= 1: nothing flagged)."""
    q = np.clip(q, 0.0, 1.0)
    if kind == "scratch":
        return np.sqrt(1.0 - np.sqrt(q))  # (1 - u^2)^2 = q, across the groove
    if kind == "pit":
        return (1.0 - np.sqrt(q)) ** (1.0 / 6.0)  # (1 - u^6)^2 = q
    return np.sqrt(1.0 - np.cbrt(q))  # (1 - u^2)^3 = q


@dataclass(frozen=True)
class Detectability:
    """Per sample of the surface to inspect (k,): points_part (k, 3); sigma_mm the noise σ
    along the normal; column_mm the column pitch and spacing_mm the profile spacing on the
    surface (from the density; inf where no point came); seen whether any point came.
    pass_sample (p,) sorted and pass_share (p,): per pass over a sample, the sample and the
    share of its points that pass brought (None: one pass everywhere)."""

    points_part: np.ndarray
    sigma_mm: np.ndarray
    column_mm: np.ndarray
    spacing_mm: np.ndarray
    seen: np.ndarray
    pass_sample: np.ndarray | None = None
    pass_share: np.ndarray | None = None

    def pod_at(
        self, kind: str, size_mm: float, detector: Detector, rows: np.ndarray | None = None
    ) -> np.ndarray:
        """(k,) the probability a `kind` defect of depth `size_mm` at each sample (or at the
        sorted sample indices `rows`) is found: by any of the passes over it, each with its
        own share of the points and an offset of its own."""
        if kind not in PREDICTED:
            raise ValueError(f"no prediction for a {kind}: only {', '.join(PREDICTED)}")
        idx = np.arange(len(self.seen)) if rows is None else rows
        seen = self.seen[idx]
        sigma = np.where(seen, self.sigma_mm[idx], 1.0)
        gap = np.where(seen, self.spacing_mm[idx], 1.0)
        col = np.where(seen, self.column_mm[idx], 1.0)
        _, width, length = shape(kind, size_mm)
        rk = flagged_radius(kind, detector.k_sigma * sigma / size_mm)
        rk = np.where(seen, width / 2 * rk, 0.0)

        def share(rk: np.ndarray, gap: np.ndarray, col: np.ndarray) -> np.ndarray:
            if kind == "scratch":
                # Its ends taper over half a width each: flagged a width shorter, about.
                return _found_share_groove(rk, length - width, gap, col, detector.min_points)
            return _found_share(rk, gap, col, detector.min_points)

        if self.pass_sample is None or self.pass_share is None:
            return np.where(seen, share(rk, gap, col), 0.0)
        mask = np.isin(self.pass_sample, idx)
        pos = np.searchsorted(idx, self.pass_sample[mask])
        # A pass with a share of the points there has its profiles that much farther apart.
        gap_pass = gap[pos] / self.pass_share[mask]
        found = share(rk[pos], gap_pass, col[pos])
        log_miss = np.bincount(pos, np.log(np.maximum(1.0 - found, 1e-300)), len(idx))
        return np.where(seen, 1.0 - np.exp(log_miss), 0.0)

    def predicted_pod(
        self, kind: str, sizes_mm: np.ndarray, detector: Detector, seed: int = 0
    ) -> np.ndarray:
        """(s,) the predicted POD over the surface at each size (a subsample of samples)."""
        rows = self._rows(seed)
        return np.array([self.pod_at(kind, a, detector, rows).mean() for a in sizes_mm])

    def predicted_a(
        self, kind: str, detector: Detector, share: float = 0.9, seed: int = 0
    ) -> float | None:
        """The depth at which the predicted POD reaches `share` (None if it never does
        below 100 mm: too much of the surface unseen)."""
        rows = self._rows(seed)
        seen = self.seen if rows is None else self.seen[rows]
        if not seen.mean() >= share:  # unseen samples never find a defect
            return None
        grid = np.geomspace(1e-4, 100.0, 145)
        previous = 0.0
        for i, a in enumerate(grid):
            pod = float(self.pod_at(kind, a, detector, rows).mean())
            if pod >= share:
                if i == 0:
                    return float(a)
                # Interpolate in log size between the grid's neighbours.
                w = (share - previous) / max(pod - previous, 1e-12)
                return float(math.exp(math.log(grid[i - 1]) + w * math.log(a / grid[i - 1])))
            previous = pod
        return None

    def smallest_mm(self, kind: str, detector: Detector, share: float = 0.9) -> np.ndarray:
        """(k,) per sample the smallest depth found with probability `share` (inf: none
        below 100 mm)."""
        grid = np.geomspace(1e-3, 100.0, 61)
        out = np.full(len(self.seen), np.inf)
        todo = np.flatnonzero(self.seen)
        for a in grid:
            if len(todo) == 0:
                break
            now = self.pod_at(kind, a, detector, todo) >= share
            out[todo[now]] = a
            todo = todo[~now]
        return out

    def _rows(self, seed: int) -> np.ndarray | None:
        k = len(self.seen)
        if k <= MAX_PREDICTED_SAMPLES:
            return None
        return np.sort(np.random.default_rng(seed).choice(k, MAX_PREDICTED_SAMPLES, False))

    def to_json_dict(self) -> dict[str, Any]:
        seen = self.seen
        return {
            "samples": len(seen),
            "seen_share": float(seen.mean()) if len(seen) else 0.0,
            "median_sigma_mm": _median(self.sigma_mm[seen]),
            "median_column_mm": _median(self.column_mm[seen]),
            "median_spacing_mm": _median(self.spacing_mm[seen]),
        }


def _found_share(rk: np.ndarray, gap: np.ndarray, col: np.ndarray, min_points: int) -> np.ndarray:
    """(k,) the share of profile offsets for which a disc of radius rk, crossed by profiles
    `gap` apart and sampled `col` apart along them, holds `min_points` points."""
    ratio = rk / gap
    # Far more than a few profiles across the disc: the count is its area's.
    wide = ratio > WIDE_PROFILES
    reach = int(np.ceil(np.max(np.where(wide, 0.0, ratio), initial=0.0))) + 1
    j = np.arange(-reach, reach + 1)
    found = np.zeros(len(rk))
    for i in range(OFFSETS):
        u = ((i + 0.5) / OFFSETS + j[None, :]) * gap[:, None]  # (k, j) profiles' offsets
        chord = 2.0 * np.sqrt(np.maximum(rk[:, None] ** 2 - u**2, 0.0))
        found += (chord / col[:, None]).sum(axis=1) >= min_points
    area_count = np.pi * rk**2 / (gap * col)
    return np.where(wide, (area_count >= min_points).astype(float), found / OFFSETS)


def _found_share_groove(
    hk: np.ndarray, length: float, gap: np.ndarray, col: np.ndarray, min_points: int
) -> np.ndarray:
    """(k,) the share of profile offsets and directions for which a groove `length` long,
    flagged over a half-width hk, crossed by profiles `gap` apart and sampled `col` apart
    along them, holds `min_points` points."""
    found = np.zeros(len(hk))
    for a in range(ANGLES):
        phi = (a + 0.5) / ANGLES * np.pi / 2  # to the scan direction
        cos, sin = np.cos(phi), np.sin(phi)
        extent = length * cos + 2.0 * hk * sin  # along the scan: what the profiles cross
        chord = np.minimum(2.0 * hk / max(cos, 1e-9), length / max(sin, 1e-9))
        per_crossing = np.where(hk > 0, chord / col, 0.0)
        for i in range(OFFSETS):
            crossings = np.floor(extent / gap + (i + 0.5) / OFFSETS)
            found += crossings * per_crossing >= min_points
    return found / (ANGLES * OFFSETS)


def _median(values: np.ndarray) -> float | None:
    return float(np.median(values)) if len(values) else None


def survey(
    part: Part,
    sensor: SensorSpec,
    poses: np.ndarray,
    detector: Detector,
    surface: VisibleSurface,
    seed: int = 0,
    chunk_poses: int = 256,
    progress: Callable[[int, int], None] | None = None,
    swath: np.ndarray | None = None,
) -> tuple[FalseCalls, Detectability]:
    """Scan the defect-free `part` (restricted to its surface to inspect) along the plan's
    scanning `poses`: the calls it makes, every one false, and the detectability at each
    sample of `surface`; swath (m,): the pass of each pose (None: one pass)."""
    profiler = LineProfilometer(part, sensor, seed=seed)
    samples = surface.points
    tree = cKDTree(samples)
    k = len(samples)
    count = np.zeros(k)
    sig_sum, col_sum, n_sum = np.zeros(k), np.zeros(k), np.zeros(k)
    kept: list[np.ndarray] = []
    n_flag = n_valid = 0
    pass_of = np.zeros(len(poses), np.int64) if swath is None else np.asarray(swath, np.int64)
    pass_of = np.unique(pass_of, return_inverse=True)[1]
    n_pass = int(pass_of.max(initial=0)) + 1
    pair_keys: list[np.ndarray] = []
    pair_counts: list[np.ndarray] = []
    for lo, scan in profiler.measure_in_chunks(poses, chunk_poses, progress):
        hit = flagged(scan, scan.true_z_sensor, sensor, detector.k_sigma)
        kept.append(scan.points_part[hit])
        valid = scan.valid
        n_flag += int(hit.sum())
        n_valid += int(valid.sum())
        sig_n = sigma_mm(scan, sensor) * cos_incidence(scan, sensor)
        col = np.full(valid.shape, np.nan)
        col[:, :-1] = np.linalg.norm(np.diff(scan.points_part, axis=1), axis=2)
        col[:, :-1][~(valid[:, 1:] & valid[:, :-1])] = np.nan
        pick = (slice(None), slice(None, None, COLUMN_STRIDE))
        v = valid[pick]
        pts = scan.points_part[pick][v]
        point_pass = pass_of[lo + np.nonzero(v)[0]]
        if len(pts) == 0:
            continue
        lo, hi = pts.min(axis=0) - DENSITY_RADIUS_MM, pts.max(axis=0) + DENSITY_RADIUS_MM
        inside = np.flatnonzero(np.all((samples >= lo) & (samples <= hi), axis=1))
        count[inside] += COLUMN_STRIDE * np.asarray(
            cKDTree(pts).query_ball_point(samples[inside], DENSITY_RADIUS_MM, return_length=True)
        )
        dist, near = tree.query(pts, distance_upper_bound=DENSITY_RADIUS_MM)
        ok = np.isfinite(dist)
        c, s = col[pick][v][ok], sig_n[pick][v][ok]
        good = np.isfinite(c) & np.isfinite(s)
        near = near[ok][good]
        keys, counts = np.unique(near * n_pass + point_pass[ok][good], return_counts=True)
        pair_keys.append(keys)
        pair_counts.append(counts)
        sig_sum += np.bincount(near, s[good], k)
        col_sum += np.bincount(near, c[good], k)
        n_sum += np.bincount(near, minlength=k)
    points = np.concatenate(kept) if kept else np.zeros((0, 3))
    false = FalseCalls(len(calls(points, detector)), n_flag, n_valid, surface.area_mm2)
    seen = (n_sum > 0) & (count > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        sigma = np.where(seen, sig_sum / n_sum, np.inf)
        column = np.where(seen, col_sum / n_sum, np.inf)
        density = count / (math.pi * DENSITY_RADIUS_MM**2)
        spacing = np.where(seen, 1.0 / (density * column), np.inf)
    keys = np.concatenate(pair_keys) if pair_keys else np.zeros(0, np.int64)
    counts = np.concatenate(pair_counts) if pair_counts else np.zeros(0, np.int64)
    keys, inverse = np.unique(keys, return_inverse=True)
    counts = np.bincount(inverse, counts, len(keys))
    pass_sample = keys // n_pass
    total = np.bincount(pass_sample, counts, k)
    share = counts / np.maximum(total[pass_sample], 1.0)
    return false, Detectability(samples, sigma, column, spacing, seen, pass_sample, share)
