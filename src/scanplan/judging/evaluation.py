"""`evaluate`: simulate the scan of a trajectory and summarize it. Every scanning pose is
measured in chunks and streamed through the accumulators, so a full 4096-column scan of the
door fits in memory.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from typing import Any, Protocol

import numpy as np

from scanplan.core.context import PlanContext, recorded
from scanplan.core.cycle import NOMINAL, MotionLimits, cycle_time
from scanplan.core.quantities import ScanSpec, point_orientation_error
from scanplan.core.sensor_spec import SensorSpec
from scanplan.core.trajectory import Trajectory
from scanplan.judging.accumulators import CloudSample, Coverage, PointErrors, Spacing
from scanplan.judging.summary import Metrics, SurfaceState
from scanplan.sensor.profilometer import LineProfilometer, Scan
from scanplan.world.cell import Cell, part_in_cell, planned_cell
from scanplan.world.collision import checker_for
from scanplan.world.part import Part
from scanplan.world.surface import (
    VisibleSurface,
    hemisphere_visible_samples,
    oriented_normals,
    reachable_samples,
    upward_visible_samples,
)


class ScanObserver(Protocol):
    """Something more to learn from the scan `evaluate` simulates (the detectability map,
    `survey.DetectabilitySurvey`), fed the same chunks: no second scan."""

    def start(
        self, surface: VisibleSurface, fan: SensorSpec, swath: np.ndarray | None = None
    ) -> None: ...

    def add(self, lo: int, scan: Scan) -> None: ...


def coverage_spacing_mm(sensor: SensorSpec) -> float:
    """The spacing of the coverage samples `evaluate` draws for a fan of this sensor."""
    lateral_spacing = sensor.line_width_mm / max(sensor.points_per_profile - 1, 1)
    return max(2.0, 1.2 * lateral_spacing)


def _path_summary(
    traj: Trajectory,
    scan_spec: ScanSpec,
    limits: MotionLimits,
    targets: np.ndarray | None,
    blended: np.ndarray | None,
) -> dict[str, Any]:
    scan_len = float(
        np.linalg.norm(np.diff(traj.positions_mm, axis=0), axis=1)[
            traj.scanning[1:] & traj.scanning[:-1] & (traj.swath[1:] == traj.swath[:-1])
        ].sum()
    )
    path_len = traj.path_length_mm()
    cycle = cycle_time(traj, scan_spec, limits, targets=targets, blended=blended)
    return {
        "path_length_mm": path_len,
        "scan_length_mm": scan_len,
        "move_length_mm": path_len - scan_len,
        "cycle_time_s": cycle.total_s,
        "scan_time_s": cycle.scanning_s,
        "move_time_s": cycle.moving_s,
        "cycle": cycle,
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


def scanning_steps(traj: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """(m,) the indices of the scanning poses and (m,) bool whether each is a step: it and
    the previous pose of the trajectory scan in the same pass."""
    scan_idx = np.flatnonzero(traj.scanning)
    swath = traj.swath[scan_idx]
    has_prev = np.zeros(len(scan_idx), bool)
    has_prev[1:] = (swath[1:] == swath[:-1]) & (np.diff(scan_idx) == 1)
    return scan_idx, has_prev


def surface_samples(
    part: Part, spec: SensorSpec, context: PlanContext, seed: int
) -> VisibleSurface:
    """The samples of the surface to inspect that (in-spec) coverage is counted on; `part`
    already restricted to the context's region of interest, `spec` the evaluated fan."""
    sampler = upward_visible_samples if context.visible == "top" else hemisphere_visible_samples
    return sampler(part, coverage_spacing_mm(spec), seed)


def coverage_of(
    surface: VisibleSurface,
    scan_spec: ScanSpec,
    spec: SensorSpec,
    normals: np.ndarray,
    plain: bool = True,
) -> Coverage:
    """The coverage accumulator for a scan by the evaluated fan `spec` (perhaps sub-sampled);
    normals: (k, 3) the samples' outward normals (`surface.oriented_normals`); plain: as
    `Coverage`'s."""
    lateral_spacing = spec.line_width_mm / max(spec.points_per_profile - 1, 1)
    # Decimate the points used for coverage to ~1/3 of the sample spacing: same answer, faster.
    col_stride = max(1, int(coverage_spacing_mm(spec) / 3 / lateral_spacing))
    # Wide enough that every sample between two measured lines has a point within reach.
    cover_radius = max(1.0, lateral_spacing * col_stride)
    in_spec_radius = in_spec_radius_mm(scan_spec, lateral_spacing * col_stride)
    return Coverage(surface, scan_spec, col_stride, cover_radius, in_spec_radius, normals, plain)


def _visibility_ceiling(
    part: Part, surface: VisibleSurface, scan_spec: ScanSpec, seed: int
) -> float | None:
    """The share of the surface samples a sensor could see within the angle tolerance (past
    the part's fixtures, with `part` in its cell); None where there is no sample."""
    if not len(surface.points):
        return None
    # On the very samples in-spec coverage counts, so the two shares compare.
    reachable = reachable_samples(part, surface, scan_spec.tol_angle_rad, seed=seed)
    return float(reachable.mean())


def _collision_summary(
    part: Part, sensor: SensorSpec, cell: Cell, traj: Trajectory, scan_spec: ScanSpec
) -> dict[str, Any]:
    """The collision figures of `Metrics`: the sensor at every pose of `traj` against the part
    and the cell the plan was made in, kept `scan_spec.clearance_mm` clear."""
    checker = checker_for(part, sensor, cell)
    collisions = checker.check(traj.poses, scan_spec.clearance_mm)
    return {
        "collisions_count": int(collisions.colliding.sum()),
        "collisions_touching": int(collisions.touching.sum()),
        "collisions_table": int(collisions.colliding_with("table").sum()),
        "collisions_fixtures": int(collisions.colliding_with("fixtures").sum()),
        "worst_penetration_mm": collisions.worst_penetration_mm,
        "clearance_mm": collisions.clearance_mm,
    }


def _judge(
    chunks: Iterator[tuple[int, Scan]],
    coverage: Coverage,
    has_prev: np.ndarray,
    beside_coverage: Callable[[int, Scan, np.ndarray], None],
    aside: Sequence[Callable[[], Any]],
) -> list[Any]:
    """Judge the scan's `chunks` here, the `coverage` then the other accumulators
    (`beside_coverage`; the coverage builds the tree the survey shares), while the next
    chunk is measured (`measure_in_chunks`): two threads on two cores. Judging a chunk on
    two threads of its own left the measuring a core's share of three. The jobs `aside`,
    which do not need the scan (the collisions, the ceiling), run on a third thread from
    the start: it has a core while the first chunk is measured. Returns their results."""
    with ThreadPoolExecutor(max_workers=1) as beside:
        aside_jobs = [beside.submit(job) for job in aside]
        for lo, scan in chunks:
            ori = point_orientation_error(scan.normals_part, scan.poses)
            coverage.add(scan, ori, has_prev[lo : lo + len(scan)])
            beside_coverage(lo, scan, ori)
        return [job.result() for job in aside_jobs]


def _out_of_reach(part: Part) -> ValueError:
    hidden = " or hidden by its fixtures" if part.occluders else ""
    return ValueError(
        f"no valid point: part {part.name} is outside the sensor's reach along this trajectory"
        + hidden
    )


def in_spec_samples(
    part: Part,
    scan_spec: ScanSpec,
    traj: Trajectory,
    seed: int = 0,
    points_per_profile: int | None = None,
    context: PlanContext | None = None,
) -> np.ndarray:
    """Which of the surface samples `evaluate` draws (same seed, fan and context) the scan of
    `traj` holds in spec, (k,) bool: its in-spec map alone, for choosing views and fitting an
    arm, in about 0.6x `evaluate`'s time (the door). Each pass is measured on its own (a
    sample's in-spec state depends on one pass's points), on a thread per core, its noise
    drawn from its own child of `seed`: the same set whatever the number of cores, within
    the noise of `evaluate`'s. Raises ValueError, as `evaluate` does, if no scanning pose
    returns a valid point. The part's fixtures (the context's cell, unless `part` is among
    occluders already: `cell.part_in_cell`) hide it from the sensor."""
    sensor = scan_spec.sensor
    spec = sensor.with_points(points_per_profile) if points_per_profile else sensor
    if not traj.scanning.any():
        raise ValueError("trajectory has no scanning pose")
    scan_idx, has_prev = scanning_steps(traj)
    poses = traj.poses[scan_idx]
    context = recorded(traj, scan_spec) if context is None else context
    part = part.with_roi(context.roi)
    surface = surface_samples(part, spec, context, seed)
    if not len(surface.points):
        return np.zeros(0, bool)
    in_cell = part_in_cell(context, part)  # what the sensor meets: the part among its fixtures
    normals = oriented_normals(part)[surface.faces]
    # A pass starts wherever the pass index changes: the in-spec test looks no further.
    swath = traj.swath[scan_idx]
    starts = np.flatnonzero(np.r_[True, swath[1:] != swath[:-1]])
    bounds = list(zip(starts, np.r_[starts[1:], len(poses)], strict=True))
    seeds = np.random.SeedSequence(seed).generate_state(len(bounds))

    def one_pass(k: int) -> tuple[np.ndarray, bool]:
        lo, hi = bounds[k]
        coverage = coverage_of(surface, scan_spec, spec, normals, plain=False)
        profiler = LineProfilometer(in_cell, spec, seed=int(seeds[k]), threads=1)
        seen = False
        for at, scan in profiler.measure_in_chunks(poses[lo:hi]):
            ori = point_orientation_error(scan.normals_part, scan.poses)
            coverage.add(scan, ori, has_prev[lo + at : lo + at + len(scan)])
            seen = seen or bool(scan.valid.any())
        return coverage.finish()[2].state == SurfaceState.IN_SPEC, seen

    held = np.zeros(len(surface.points), bool)
    seen = False
    with ThreadPoolExecutor(max_workers=min(len(bounds), os.cpu_count() or 1)) as pool:
        for pass_held, pass_seen in pool.map(one_pass, range(len(bounds))):
            held |= pass_held
            seen |= pass_seen
    if not seen:
        raise _out_of_reach(in_cell)
    return held


def evaluate(
    part: Part,
    scan_spec: ScanSpec,
    traj: Trajectory,
    seed: int = 0,
    points_per_profile: int | None = None,
    chunk_poses: int = 256,
    max_map_points: int = 200_000,
    progress: Callable[[int, int], None] | None = None,
    context: PlanContext | None = None,
    limits: MotionLimits = NOMINAL,
    targets: np.ndarray | None = None,
    blended: np.ndarray | None = None,
    ceiling: bool = True,
    observers: Sequence[ScanObserver] = (),
) -> Metrics:
    """Simulate the scan of `traj` and summarize it (SPEC §7).

    points_per_profile: sub-sample the fan for a faster evaluation (same line width); the in-spec
    density rule still judges the real sensor's columns. progress(done, total): called after
    each chunk of scanning poses (a caller's progress bar).
    context: what the plan is judged as (its surface to inspect, region of interest and
    reward); None: as recorded in the trajectory (`context.recorded`). Every statistic is
    over the part's surface to inspect: points on other faces count as no hit; the context's
    fixtures hide it from the sensor and the ceiling's beams, not from that surface.
    limits, targets, blended: the arm's motion limits the cycle time is timed with, the poses
    a program flies between and those it blends through (`cycle.cycle_time`; None: every
    planned pose, each an exact stop).
    ceiling: also measure the visibility ceiling of the surface to inspect (beside the scan).
    observers: each started on the surface samples, the fan and the scanning poses' passes,
    then fed every chunk of the scan. Raises ValueError if no scanning pose sees a point."""
    start_time = time.perf_counter()
    sensor = scan_spec.sensor
    spec = sensor.with_points(points_per_profile) if points_per_profile else sensor
    n_cols = spec.points_per_profile
    wd = spec.working_distance_mm
    if not traj.scanning.any():
        raise ValueError("trajectory has no scanning pose")
    scan_idx, has_prev = scanning_steps(traj)
    poses = traj.poses[scan_idx]
    swath = traj.swath[scan_idx]
    # The scan direction y_s says which way is forward (only the sign of Δs uses it): on a
    # side view's pass up a wall the horizontal has no forward.
    u_dir = poses[:, :3, 1].copy()
    context = recorded(traj, scan_spec) if context is None else context
    part = part.with_roi(context.roi)
    surface = surface_samples(part, spec, context, seed)
    cell = planned_cell(context, part)
    in_cell = cell.occluding(part)  # what the sensor meets: the part among its fixtures

    errors = PointErrors(wd, spec.z_range_mm)
    spacing = Spacing(u_dir, has_prev, context.full_beam_angle)
    coverage = coverage_of(surface, scan_spec, spec, oriented_normals(part)[surface.faces])
    sample = CloudSample(len(poses) * n_cols, max_map_points, seed)
    for observer in observers:
        observer.start(surface, spec, swath)

    def beside_coverage(lo: int, scan: Scan, ori: np.ndarray) -> None:
        errors.add(scan, ori)
        spacing.add(lo, scan)
        sample.add(lo, scan, ori, swath[lo : lo + len(scan)], wd)
        for observer in observers:
            observer.add(lo, scan)

    chunks = LineProfilometer(in_cell, spec, seed=seed).measure_in_chunks(
        poses, chunk_poses, progress
    )
    aside: list[Callable[[], Any]] = [
        partial(_collision_summary, part, sensor, cell, traj, scan_spec),
        partial(_path_summary, traj, scan_spec, limits, targets, blended),
    ] + ([partial(_visibility_ceiling, in_cell, surface, scan_spec, seed)] if ceiling else [])
    collided, path, *ceiling_found = _judge(chunks, coverage, has_prev, beside_coverage, aside)
    if errors.n_valid == 0:
        raise _out_of_reach(in_cell)
    coverage_fraction, in_spec_fraction, coverage_map = coverage.finish()
    return Metrics(
        part=part.name,
        planner=traj.planner,
        sensor=spec.name,
        profiles=len(poses),
        points_per_profile=n_cols,
        coverage_fraction=coverage_fraction,
        coverage_radius_mm=coverage.cover_radius,
        surface=context.surface,
        visible_area_mm2=surface.area_mm2,
        in_spec_coverage=in_spec_fraction,
        visibility_ceiling=ceiling_found[0] if ceiling_found else None,
        in_spec_radius_mm=coverage.in_spec_radius,
        in_spec_cell_mm=2.0 * scan_spec.delta_s_opt_mm,
        tolerance_mm=scan_spec.tolerance_mm,
        tolerance_deg=math.degrees(scan_spec.tol_angle_rad),
        eval_time_s=time.perf_counter() - start_time,
        cloud=sample.cloud(),
        coverage_map=coverage_map,
        **collided,
        **errors.summary(),
        **spacing.summary(wd, scan_spec),
        **path,
    )
