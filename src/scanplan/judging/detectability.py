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

from scanplan.judging.detection import (
    Detector,
)
from scanplan.sensor.defects import KINDS, shape

PREDICTED = KINDS  # every defect type has a prediction
ANGLES = 8  # a scratch's directions to the scan averaged over
DENSITY_RADIUS_MM = 2.0
NEAREST_POINTS = 8  # a sample's noise, pitch and passes: from its nearest points in a chunk
COLUMN_STRIDE = 4  # the density is counted on every 4th column (x 4)
OFFSETS = 16  # profile offsets averaged over, per sample (a multiple of 8: counted by words)
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
        self,
        kind: str,
        detector: Detector,
        share: float = 0.9,
        seed: int = 0,
        pod: Callable[[float | np.ndarray], np.ndarray] | None = None,
    ) -> float | None:
        """The depth at which the predicted POD reaches `share` (None if it never does
        below 100 mm: too much of the surface unseen); pod: `pod_function` of the kind,
        detector and `sampled_rows(seed)`, if the caller has it."""
        rows = self.sampled_rows(seed)
        seen = self.seen if rows is None else self.seen[rows]
        if not seen.mean() >= share:  # unseen samples never find a defect
            return None
        pod = pod or self.pod_function(kind, detector, rows)
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
        self,
        kind: str,
        detector: Detector,
        share: float = 0.9,
        rows: np.ndarray | None = None,
        pod: Callable[[float | np.ndarray], np.ndarray] | None = None,
    ) -> np.ndarray:
        """(k,) per sample (or (r,) per sorted sample index of `rows`) the smallest depth
        found with probability `share` (inf: none below 100 mm); pod: `pod_function` of the
        kind, detector and rows, if the caller has it."""
        pod = pod or self.pod_function(kind, detector, rows)
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
    # Looked up in rising order: np.interp starts each search where the last one ended, so
    # sorted values cost a tenth (each value's answer is its own, in any order).
    order = np.argsort(need)
    rising = need[order]
    out = np.empty((len(gap), OFFSETS))
    for i in range(OFFSETS):
        s = sums[:, i]
        first = int(np.searchsorted(s, 0.0, side="right")) - 1  # S strictly rises from here
        out[order, i] = np.interp(rising, s[first:], rho[first:], right=np.inf)
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
    found = _share_of_offsets(ratio[:, None] >= crossing)
    area_count = np.pi * rk**2 / (gap * col)
    return np.where(wide, (area_count >= min_points).astype(float), found)


def _share_of_offsets(found: np.ndarray) -> np.ndarray:
    """(k,) the share of True in each row of (k, `OFFSETS`) bool, as `found.mean(axis=1)`
    to the last bit (whole counts over 16): counted 8 bytes at a time, at a third of the
    cost of numpy's reduction along rows of 16."""
    words = np.bitwise_count(np.ascontiguousarray(found).view(np.uint64))  # bools are 0 or 1
    count = words[:, 0].astype(np.int64)
    for column in words.T[1:]:  # OFFSETS / 8 columns: a reduction along rows of 2 is slow
        count += column
    return count / OFFSETS


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
