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
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from scanplan.core.quantities import DEFECT_TYPE, ScanSpec, norm_rows
from scanplan.core.sensor_spec import SensorSpec
from scanplan.core.trajectory import Trajectory
from scanplan.judging.accumulators import valid_points, valid_points_tree
from scanplan.judging.detection import (
    Detector,
    FalseCalls,
    calls,
    cos_incidence,
    detector_for,
    flagged,
    sigma_mm,
)
from scanplan.judging.evaluation import evaluate
from scanplan.judging.summary import Metrics
from scanplan.sensor.defects import KINDS, shape
from scanplan.sensor.profilometer import LineProfilometer, Scan
from scanplan.world.part import Part
from scanplan.world.surface import VisibleSurface

PREDICTED = KINDS  # every defect type has a prediction
ANGLES = 8  # a scratch's directions to the scan averaged over
DENSITY_RADIUS_MM = 2.0
NEAREST_POINTS = 8  # a sample's noise, pitch and passes: from its nearest points in a chunk
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


def predicted_rows(k: int, seed: int) -> np.ndarray | None:
    """Sorted indices of the seeded sample of `MAX_PREDICTED_SAMPLES` of k samples the
    predictions are made on (None: all of them, being no more)."""
    if k <= MAX_PREDICTED_SAMPLES:
        return None
    return np.sort(np.random.default_rng(seed).choice(k, MAX_PREDICTED_SAMPLES, False))


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
        self,
        kind: str,
        size_mm: float | np.ndarray,
        detector: Detector,
        rows: np.ndarray | None = None,
    ) -> np.ndarray:
        """(k,) the probability a `kind` defect of depth `size_mm` (one, or one per sample)
        at each sample (or at the sorted sample indices `rows`) is found: by any of the
        passes over it, each with its own share of the points and an offset of its own."""
        return self.pod_function(kind, detector, rows)(size_mm)

    def pod_function(
        self, kind: str, detector: Detector, rows: np.ndarray | None = None
    ) -> Callable[[float | np.ndarray], np.ndarray]:
        """`pod_at` for one kind, detector and rows, as a function of the depth: what does
        not depend on the depth (the samples' passes) is gathered once, not per depth."""
        if kind not in PREDICTED:
            raise ValueError(f"no prediction for a {kind}: only {', '.join(PREDICTED)}")
        idx = np.arange(len(self.seen)) if rows is None else rows
        seen = self.seen[idx]
        sigma = np.where(seen, self.sigma_mm[idx], 1.0)
        gap = np.where(seen, self.spacing_mm[idx], 1.0)
        col = np.where(seen, self.column_mm[idx], 1.0)
        if self.pass_sample is None or self.pass_share is None:
            pos = np.arange(len(idx))
            gap_pass = gap
        else:
            mask = np.isin(self.pass_sample, idx)
            pos = np.searchsorted(idx, self.pass_sample[mask])
            # A pass with a share of the points there has its profiles that much farther apart.
            gap_pass = gap[pos] / self.pass_share[mask]
        col_pass = col[pos]
        # What a disc needs to be found, per pass and offset, does not depend on its depth.
        crossing = _disc_crossing(gap_pass, col_pass, detector.min_points)

        def pod(size_mm: float | np.ndarray) -> np.ndarray:
            size = np.broadcast_to(np.asarray(size_mm, dtype=float), idx.shape)
            _, width, length = shape(kind, size)
            rk = flagged_radius(kind, detector.k_sigma * sigma / size)
            rk = np.where(seen, width / 2 * rk, 0.0)[pos]
            if kind == "scratch":
                # Its ends taper over half a width each: flagged a width shorter, about.
                found = _found_share_groove(
                    rk, (length - width)[pos], gap_pass, col_pass, detector.min_points
                )
            else:
                found = _found_share(rk, gap_pass, col_pass, detector.min_points, crossing)
            log_miss = np.bincount(pos, np.log(np.maximum(1.0 - found, 1e-300)), len(idx))
            return np.where(seen, 1.0 - np.exp(log_miss), 0.0)

        return pod

    def predicted_pod(
        self, kind: str, sizes_mm: np.ndarray, detector: Detector, seed: int = 0
    ) -> np.ndarray:
        """(s,) the predicted POD over the surface at each size (a subsample of samples)."""
        pod = self.pod_function(kind, detector, self.sampled_rows(seed))
        return np.array([pod(a).mean() for a in sizes_mm])

    def predicted_a(
        self, kind: str, detector: Detector, share: float = 0.9, seed: int = 0
    ) -> float | None:
        """The depth at which the predicted POD reaches `share` (None if it never does
        below 100 mm: too much of the surface unseen)."""
        rows = self.sampled_rows(seed)
        seen = self.seen if rows is None else self.seen[rows]
        if not seen.mean() >= share:  # unseen samples never find a defect
            return None
        pod = self.pod_function(kind, detector, rows)
        # The POD only grows with the depth: bisect on log depth (14 halvings of 1e-4..100 mm
        # leave 0.1 % of it), not a grid walk.
        lo, hi = math.log(1e-4), math.log(100.0)
        if pod(math.exp(hi)).mean() < share:
            return None
        if pod(math.exp(lo)).mean() >= share:
            return math.exp(lo)
        for _ in range(14):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if pod(math.exp(mid)).mean() >= share else (mid, hi)
        return math.exp(hi)

    def smallest_mm(
        self, kind: str, detector: Detector, share: float = 0.9, rows: np.ndarray | None = None
    ) -> np.ndarray:
        """(k,) per sample (or (r,) per sorted sample index of `rows`) the smallest depth
        found with probability `share` (inf: none below 100 mm)."""
        pod = self.pod_function(kind, detector, rows)
        n = len(self.seen) if rows is None else len(rows)
        # Each sample's POD only grows with the depth: all samples bisected at once on log
        # depth, 1e-3..100 mm in 17 halvings (0.01 % apart, finer than any map shows).
        lo, hi = np.full(n, math.log(1e-3)), np.full(n, math.log(100.0))
        found_at_hi = pod(np.exp(hi)) >= share
        found_at_lo = pod(np.exp(lo)) >= share
        for _ in range(17):
            mid = 0.5 * (lo + hi)
            found = pod(np.exp(mid)) >= share
            lo, hi = np.where(found, lo, mid), np.where(found, mid, hi)
        return np.where(found_at_lo, 1e-3, np.where(found_at_hi, np.exp(hi), np.inf))

    def sampled_rows(self, seed: int) -> np.ndarray | None:
        """Sorted indices of a seeded sample of `MAX_PREDICTED_SAMPLES` samples (None: all
        of them, being no more)."""
        return predicted_rows(len(self.seen), seed)

    def to_json_dict(self) -> dict[str, Any]:
        seen = self.seen
        return {
            "samples": len(seen),
            "seen_share": float(seen.mean()) if len(seen) else 0.0,
            "median_sigma_mm": _median(self.sigma_mm[seen]),
            "median_column_mm": _median(self.column_mm[seen]),
            "median_spacing_mm": _median(self.spacing_mm[seen]),
        }


def _profile_sums() -> tuple[np.ndarray, np.ndarray]:
    """(r,) ρ from 0 to `WIDE_PROFILES` and (r, OFFSETS) S(ρ): Σ_j sqrt(ρ² − (o + j)²)⁺ for
    each profile offset o, the chord lengths (over 2 · spacing) a disc of radius ρ spacings
    holds; each column non-decreasing in ρ. Tabulated once."""
    global _SUMS
    if _SUMS is None:
        rho = np.linspace(0.0, WIDE_PROFILES, _TABLE_STEPS + 1)
        reach = int(math.ceil(WIDE_PROFILES)) + 1
        j = np.arange(-reach, reach + 1)
        offsets = (np.arange(OFFSETS) + 0.5) / OFFSETS
        u = offsets[None, :, None] + j[None, None, :]
        _SUMS = rho, np.sqrt(np.maximum(rho[:, None, None] ** 2 - u**2, 0.0)).sum(axis=2)
    return _SUMS


_TABLE_STEPS = 8192  # ρ every 0.0005 spacings: a threshold off by far less than any input's error
_SUMS: tuple[np.ndarray, np.ndarray] | None = None


def _disc_crossing(gap: np.ndarray, col: np.ndarray, min_points: int) -> np.ndarray:
    """(k, OFFSETS) the radius, in profile spacings, from which a disc crossed by profiles
    `gap` apart, sampled `col` apart along them, holds `min_points` points at each offset
    (inf: not below `WIDE_PROFILES`): the inverse of `_profile_sums`, interpolated."""
    rho, sums = _profile_sums()
    need = min_points * col / (2.0 * gap)  # S(ρ) >= need: the chords hold enough points
    out = np.empty((len(gap), OFFSETS))
    for i in range(OFFSETS):
        s = sums[:, i]
        first = int(np.searchsorted(s, 0.0, side="right")) - 1  # S strictly rises from here
        out[:, i] = np.interp(need, s[first:], rho[first:], right=np.inf)
    return np.where(need[:, None] <= 0.0, 0.0, out)


def _found_share(
    rk: np.ndarray, gap: np.ndarray, col: np.ndarray, min_points: int, crossing: np.ndarray
) -> np.ndarray:
    """(k,) the share of profile offsets for which a disc of radius rk, crossed by profiles
    `gap` apart and sampled `col` apart along them, holds `min_points` points; crossing:
    `_disc_crossing` of gap, col and min_points."""
    ratio = rk / gap
    # Far more than a few profiles across the disc: the count is its area's.
    wide = ratio > WIDE_PROFILES
    found = (ratio[:, None] >= crossing).mean(axis=1)
    area_count = np.pi * rk**2 / (gap * col)
    return np.where(wide, (area_count >= min_points).astype(float), found)


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


class DetectabilitySurvey:
    """The detectability at each sample of `surface`, streamed from a scan's chunks
    (`add`), and the calls the scan makes (`finish`; every one false on a defect-free
    part). `evaluate` feeds it its own scan (`metrics.evaluation.ScanObserver`), so the
    map costs no second scan.

    sensor: the real sensor; fan: the fan the scan is simulated with (the real one, or a
    sub-sample of it: the column pitch is then that of the real sensor's columns, as the
    density rule judges); swath (m,): the pass of each scanning pose (None: one pass);
    false_calls: also flag and cluster the points (off: the calls are not counted);
    predicted_seed: survey only the samples the predictions are made on (`predicted_rows`
    with this seed): the same predictions and map at a fifteenth of the work on the door,
    the medians of `Detectability.to_json_dict` over those samples (None: every sample)."""

    def __init__(
        self,
        sensor: SensorSpec,
        detector: Detector,
        surface: VisibleSurface | None = None,
        swath: np.ndarray | None = None,
        false_calls: bool = True,
        predicted_seed: int | None = None,
    ) -> None:
        self.sensor = sensor
        self.predicted_seed = predicted_seed
        self.detector = detector
        self.false_calls = false_calls
        self.swath = swath
        self.surface: VisibleSurface | None = None
        self.fan = sensor
        if surface is not None:
            self.start(surface, sensor, swath)

    def start(
        self, surface: VisibleSurface, fan: SensorSpec, swath: np.ndarray | None = None
    ) -> None:
        """Begin a scan by `fan` of the samples `surface`, its poses in passes `swath`."""
        if self.predicted_seed is not None:
            rows = predicted_rows(len(surface.points), self.predicted_seed)
            if rows is not None:
                surface = VisibleSurface(
                    surface.points[rows], surface.area_mm2, surface.faces[rows]
                )
        self.surface, self.fan = surface, fan
        swath = self.swath if swath is None else swath
        k = len(surface.points)
        self._count = np.zeros(k)
        self._sig_sum, self._col_sum, self._n_sum = np.zeros(k), np.zeros(k), np.zeros(k)
        self._kept: list[np.ndarray] = []
        self._n_flag = self._n_valid = 0
        self._pass_of = None if swath is None else np.unique(swath, return_inverse=True)[1]
        self._n_pass = 1 if self._pass_of is None else int(self._pass_of.max(initial=0)) + 1
        self._pair_keys: list[np.ndarray] = []
        self._pair_counts: list[np.ndarray] = []
        # Real columns per fan column: the fan's pitch over the real sensor's.
        self._pitch_ratio = max(self.sensor.points_per_profile - 1, 1) / max(
            fan.points_per_profile - 1, 1
        )
        self._stride = max(1, round(COLUMN_STRIDE / self._pitch_ratio))
        # Points are counted in a disc several counted columns wide: a sparse fan's count
        # would jump with where its columns fall.
        pitch = fan.line_width_mm / max(fan.points_per_profile - 1, 1)
        self._radius = max(DENSITY_RADIUS_MM, 2.0 * self._stride * pitch)

    def add(self, lo: int, scan: Scan) -> None:
        """The chunk of scanning poses lo, lo+1, ... measured."""
        if self.surface is None:
            raise RuntimeError("DetectabilitySurvey.start was not called")
        fan, samples, k = self.fan, self.surface.points, len(self.surface.points)
        valid = scan.valid
        if self.false_calls:
            hit = flagged(scan, scan.true_z_sensor, fan, self.detector.k_sigma)
            self._kept.append(scan.points_part[hit])
            self._n_flag += int(hit.sum())
        self._n_valid += int(valid.sum())
        cos = cos_incidence(scan, fan)
        sig_n = sigma_mm(scan, fan, cos) * cos
        col = np.full(valid.shape, np.nan)
        col[:, :-1] = norm_rows(np.diff(scan.points_part, axis=1))
        col[:, :-1][~(valid[:, 1:] & valid[:, :-1])] = np.nan
        pick = (slice(None), slice(None, None, self._stride))
        v = valid[pick]
        # The coverage's tree where its stride is this one (the same points).
        pts = valid_points(scan, self._stride)
        if len(pts) == 0:
            return
        rows = lo + np.nonzero(v)[0]
        point_pass = np.zeros(len(pts), np.int64) if self._pass_of is None else self._pass_of[rows]
        inside = self.surface.near(pts, self._radius)  # those within reach, and some more
        if len(inside) == 0:
            return
        # One worker: the next chunk is measured on the other core meanwhile.
        near_tree = valid_points_tree(scan, self._stride)
        self._count[inside] += self._stride * np.asarray(
            near_tree.query_ball_point(samples[inside], self._radius, return_length=True)
        )
        # Each sample's noise, pitch and passes from its nearest points (not each point's
        # nearest sample: a sub-sampled fan's columns may lie farther apart than the samples).
        dist, j = near_tree.query(
            samples[inside], k=NEAREST_POINTS, distance_upper_bound=self._radius
        )
        c, s = col[pick][v], sig_n[pick][v]
        j = np.where(np.isfinite(dist), j, 0)
        good = np.isfinite(dist) & np.isfinite(c[j]) & np.isfinite(s[j])
        sample = np.broadcast_to(inside[:, None], good.shape)[good]
        j = j[good]
        keys, counts = np.unique(sample * self._n_pass + point_pass[j], return_counts=True)
        self._pair_keys.append(keys)
        self._pair_counts.append(counts)
        self._sig_sum += np.bincount(sample, s[j], k)
        self._col_sum += np.bincount(sample, c[j], k)
        self._n_sum += np.bincount(sample, minlength=k)

    def finish(self) -> tuple[FalseCalls | None, Detectability]:
        """The calls (None unless `false_calls`) and the detectability at every sample."""
        if self.surface is None:
            raise RuntimeError("DetectabilitySurvey.start was not called")
        k, n_pass = len(self.surface.points), self._n_pass
        false = None
        if self.false_calls:
            points = np.concatenate(self._kept) if self._kept else np.zeros((0, 3))
            found = len(calls(points, self.detector))
            false = FalseCalls(found, self._n_flag, self._n_valid, self.surface.area_mm2)
        n_sum = self._n_sum
        seen = (n_sum > 0) & (self._count > 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            sigma = np.where(seen, self._sig_sum / n_sum, np.inf)
            column = np.where(seen, self._col_sum / n_sum, np.inf)  # the fan's pitch
            density = self._count / (math.pi * self._radius**2)
            spacing = np.where(seen, 1.0 / (density * column), np.inf)
        column = column / self._pitch_ratio  # the real sensor's columns
        keys = np.concatenate(self._pair_keys) if self._pair_keys else np.zeros(0, np.int64)
        counts = np.concatenate(self._pair_counts) if self._pair_counts else np.zeros(0)
        keys, inverse = np.unique(keys, return_inverse=True)
        counts = np.bincount(inverse, counts, len(keys))
        pass_sample = keys // n_pass
        total = np.bincount(pass_sample, counts, k)
        share = counts / np.maximum(total[pass_sample], 1.0)
        return false, Detectability(
            self.surface.points, sigma, column, spacing, seen, pass_sample, share
        )


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
    acc = DetectabilitySurvey(sensor, detector, surface, swath)
    for lo, scan in LineProfilometer(part, sensor, seed=seed).measure_in_chunks(
        poses, chunk_poses, progress
    ):
        acc.add(lo, scan)
    false, detectability = acc.finish()
    assert false is not None
    return false, detectability


def evaluate_detectable(
    part: Part,
    scan_spec: ScanSpec,
    traj: Trajectory,
    seed: int = 0,
    points_per_profile: int | None = None,
    kind: str = DEFECT_TYPE,
    **kwargs: Any,
) -> Metrics:
    """`evaluate`, and from the same scan the `kind` defect the plan would find: its
    predicted a50 and a90 over the surface to inspect (`Metrics.detectable`) and the
    smallest depth found at 90 % on a seeded sample of the surface (`Metrics.
    detectable_map`), at the plan's call rule (`detection.detector_for`)."""
    detector = detector_for(traj, scan_spec.sensor)
    acc = DetectabilitySurvey(scan_spec.sensor, detector, false_calls=False, predicted_seed=seed)
    metrics = evaluate(part, scan_spec, traj, seed, points_per_profile, observers=[acc], **kwargs)
    _, found = acc.finish()
    picked = found.sampled_rows(seed)
    rows = np.arange(len(found.seen)) if picked is None else picked
    detectable = {
        "type": kind,
        "a50_mm": found.predicted_a(kind, detector, 0.5, seed),
        "a90_mm": found.predicted_a(kind, detector, 0.9, seed),
        "detector": detector.to_json_dict(),
        **found.to_json_dict(),
    }
    smallest = found.smallest_mm(kind, detector, 0.9, rows)
    return replace(
        metrics, detectable=detectable, detectable_map=(found.points_part[rows], smallest)
    )
