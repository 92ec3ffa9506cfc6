"""The detectability of a plan's scan, surveyed: the points' density, the noise along the
normal and the passes at each sample of the surface to inspect, streamed from the scan's
chunks (`evaluate` feeds its own scan, so the map costs no second scan), and the defect the
plan would find (`evaluate_detectable`; the model is `detectability`'s).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from scanplan.core.quantities import DEFECT_TYPE, ScanSpec, norm_rows
from scanplan.core.sensor_spec import SensorSpec
from scanplan.core.trajectory import Trajectory
from scanplan.judging.chunks import (
    rows,
    samples_near,
    valid_cells,
    valid_points,
    valid_points_tree,
)
from scanplan.judging.detectability import (
    COLUMN_STRIDE,
    DENSITY_RADIUS_MM,
    NEAREST_POINTS,
    Detectability,
    predicted_rows,
)
from scanplan.judging.detection import (
    Detector,
    FalseCalls,
    calls,
    cos_incidence_at,
    depth_sigma_mm,
    detector_for,
    flagged,
)
from scanplan.judging.evaluation import evaluate
from scanplan.judging.summary import Metrics
from scanplan.sensor.profilometer import LineProfilometer, Scan
from scanplan.world.part import Part
from scanplan.world.surface import VisibleSurface


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
        self._whole: VisibleSurface | None = None  # the surface `start` was given
        self._position: np.ndarray | None = None  # of each of its samples in `surface`, or -1
        self.fan = sensor
        if surface is not None:
            self.start(surface, sensor, swath)

    def start(
        self, surface: VisibleSurface, fan: SensorSpec, swath: np.ndarray | None = None
    ) -> None:
        """Begin a scan by `fan` of the samples `surface`, its poses in passes `swath`."""
        # The samples near a chunk are looked up on the whole surface, as the coverage
        # looks them up (once for both), then those surveyed picked out.
        self._whole, self._position = surface, None
        if self.predicted_seed is not None:
            rows = predicted_rows(len(surface.points), self.predicted_seed)
            if rows is not None:
                self._position = np.full(len(surface.points), -1)
                self._position[rows] = np.arange(len(rows))
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
        if self.surface is None or self._whole is None:
            raise RuntimeError("DetectabilitySurvey.start was not called")
        fan, samples, k = self.fan, self.surface.points, len(self.surface.points)
        valid = scan.valid
        if self.false_calls:
            hit = flagged(scan, scan.true_z_sensor, fan, self.detector.k_sigma)
            self._kept.append(scan.points_part[hit])
            self._n_flag += int(hit.sum())
        self._n_valid += int(valid.sum())
        # The coverage's tree where its stride is this one (the same points).
        pts = valid_points(scan, self._stride)
        if len(pts) == 0:
            return
        row, col = valid_cells(scan, self._stride)
        passes = self._pass_of
        point_pass = np.zeros(len(pts), np.int64) if passes is None else passes[lo + row]
        # Those within reach, and some more.
        inside = samples_near(scan, self._stride, self._whole, self._radius)
        if self._position is not None:
            inside = self._position[inside]
            inside = inside[inside >= 0]
        if len(inside) == 0:
            return
        # One worker: the next chunk is measured on the other core meanwhile.
        near_tree = valid_points_tree(scan, self._stride)
        asking = rows(samples, inside)
        self._count[inside] += self._stride * np.asarray(
            near_tree.query_ball_point(asking, self._radius, return_length=True)
        )
        # Each sample's noise, pitch and passes from its nearest points (not each point's
        # nearest sample: a sub-sampled fan's columns may lie farther apart than the samples).
        dist, j = near_tree.query(asking, k=NEAREST_POINTS, distance_upper_bound=self._radius)
        found = np.isfinite(dist)
        j = np.where(found, j, 0)
        asked = np.zeros(len(pts), bool)  # the points asked, in order: no sort
        asked[j[found]] = True
        c, s = _pitch_and_noise(scan, fan, row, col, np.flatnonzero(asked))
        good = found & np.isfinite(c[j]) & np.isfinite(s[j])
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


def _pitch_and_noise(
    scan: Scan, fan: SensorSpec, row: np.ndarray, col: np.ndarray, asked: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The column pitch (to the next column's point; NaN where either is not valid) and the
    noise σ along the normal of the valid points at (`row`, `col`) of `scan`, (k,) each, at
    the points `asked` alone (NaN elsewhere): a sample asks of its nearest few, a small
    share of the chunk's points."""
    pitch, noise = np.full(len(row), np.nan), np.full(len(row), np.nan)
    r, c = row[asked], col[asked]
    cos = cos_incidence_at(scan, fan, r, c)
    noise[asked] = depth_sigma_mm(scan.z_sensor[r, c], cos, fan) * cos
    n = scan.valid.shape[1]
    inner = c + 1 < n
    at, asked = r[inner] * n + c[inner], asked[inner]  # flat takes: a third of the cost
    points = scan.points_part.reshape(-1, 3)
    step = norm_rows(np.take(points, at + 1, 0) - np.take(points, at, 0))
    pitch[asked] = np.where(scan.valid.ravel()[at + 1], step, np.nan)
    return pitch, noise


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
    pod = found.pod_function(kind, detector, picked)  # the same rows for all three
    detectable = {
        "type": kind,
        "a50_mm": found.predicted_a(kind, detector, 0.5, seed, pod),
        "a90_mm": found.predicted_a(kind, detector, 0.9, seed, pod),
        "detector": detector.to_json_dict(),
        **found.to_json_dict(),
    }
    smallest = found.smallest_mm(kind, detector, 0.9, rows, pod)
    return replace(
        metrics, detectable=detectable, detectable_map=(found.points_part[rows], smallest)
    )


__all__ = ["DetectabilitySurvey", "evaluate_detectable", "survey"]
