"""What a plan's scan reveals: defects injected into the part (`defects`) found or missed,
and the false calls the same plan makes on the defect-free part.

A point is flagged where its measured depth departs from the NOMINAL surface's along the same
pixel column by more than k·σ, σ the simulator's own noise at that point (`NoiseModel.std_mm`
at its depth and incidence, with the depth quantization). Flagged points closer than a link
distance form a cluster; a cluster of at least `min_points` points is a call, and a defect is
found when a call has a point on it (where it displaces the surface).

A trial scans only the poses whose laser plane crosses one of its defects: the rest of the
scan is the nominal part's, whose calls are the false-call count
(`survey.survey`, which scans it once for the map too).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from scanplan.core.context import PlanContext, recorded
from scanplan.core.quantities import (
    DEFECT_K_SIGMA,
    DEFECT_MIN_POINTS,
    DEFECTS_PER_TRIAL,
    ScanSpec,
    cos_to_rays,
    normal_in_laser_plane,
)
from scanplan.core.sensor_spec import SensorSpec
from scanplan.core.trajectory import Trajectory
from scanplan.judging.evaluation import surface_samples
from scanplan.judging.pod import PodFit, fit_pod
from scanplan.judging.robustness import TrialMap
from scanplan.sensor.defects import ASPECT, Defect, inject, place
from scanplan.sensor.profilometer import LineProfilometer, Scan
from scanplan.world.cell import part_in_cell
from scanplan.world.part import Part
from scanplan.world.surface import VisibleSurface

K_SIGMA = DEFECT_K_SIGMA
MIN_POINTS = DEFECT_MIN_POINTS
# The cluster link distance over the plan's typical profile spacing.
LINK_SPACINGS = 1.5
# Poses a trial measures at once (4096 columns each: ~100 MB of arrays).
TRIAL_CHUNK_POSES = 128


@dataclass(frozen=True)
class Detector:
    """The call rule: |measured − nominal depth| > k_sigma·σ, clusters linked within
    link_mm, a call from min_points points."""

    link_mm: float
    k_sigma: float = K_SIGMA
    min_points: int = MIN_POINTS

    def to_json_dict(self) -> dict[str, float]:
        return {"k_sigma": self.k_sigma, "min_points": self.min_points, "link_mm": self.link_mm}


def profile_spacing_mm(traj: Trajectory) -> float:
    """The median distance between consecutive scanning poses of a pass (the profile spacing
    at the sensor; on the surface it is about the same for a pass that follows it)."""
    scan = traj.scanning
    same = scan[1:] & scan[:-1] & (traj.swath[1:] == traj.swath[:-1])
    steps = np.linalg.norm(np.diff(traj.positions_mm, axis=0), axis=1)[same]
    steps = steps[steps > 0]
    return float(np.median(steps)) if len(steps) else 1.0


def detector_for(traj: Trajectory, sensor: SensorSpec, **kwargs: Any) -> Detector:
    """The call rule for a plan: clusters linked over `LINK_SPACINGS` of its profile spacing
    (at least as many column pitches)."""
    pitch = sensor.line_width_mm / max(sensor.points_per_profile - 1, 1)
    link = LINK_SPACINGS * max(profile_spacing_mm(traj), pitch)
    return Detector(link_mm=link, **kwargs)


def sigma_mm(scan: Scan, sensor: SensorSpec, cos: np.ndarray | None = None) -> np.ndarray:
    """(m, N) the σ of each point's depth in the simulator: its noise model at the point's
    depth and incidence, and the depth quantization (NaN where not valid); cos: the scan's
    `cos_incidence` if the caller has it already."""
    z = np.where(scan.valid, scan.z_sensor, np.nan)
    if sensor.noise is not None and cos is None:
        cos = cos_incidence(scan, sensor)
    return np.where(scan.valid, depth_sigma_mm(z, cos, sensor), np.nan)


def depth_sigma_mm(z: np.ndarray, cos: np.ndarray | None, sensor: SensorSpec) -> np.ndarray:
    """The σ of points' depth at depths `z` and incidences `cos` (any shape; None only for a
    sensor without a noise model): the noise model and the depth quantization (`sigma_mm`
    of a whole scan)."""
    quant = sensor.z_resolution_mm / np.sqrt(12.0)
    if sensor.noise is None:
        return np.full(np.shape(z), quant)
    assert cos is not None, "a noise model needs the incidence"
    return np.hypot(sensor.noise.std_mm(z, cos, sensor.working_distance_mm), quant)


def cos_incidence(scan: Scan, sensor: SensorSpec) -> np.ndarray:
    """(m, N) |cos| of the angle between each column's ray and the surface normal it hit."""
    n_x, n_z = normal_in_laser_plane(scan.normals_part, scan.poses[:, None])
    return cos_to_rays(n_x, n_z, sensor.ray_directions())


def cos_incidence_at(
    scan: Scan, sensor: SensorSpec, row: np.ndarray, col: np.ndarray
) -> np.ndarray:
    """`cos_incidence` at the points (row, col) of the scan alone, (k,)."""
    # A flat take of the rows costs a third of numpy's two-index gather.
    flat = row * scan.normals_part.shape[1] + col
    normals = np.take(scan.normals_part.reshape(-1, 3), flat, 0)
    n_x, n_z = normal_in_laser_plane(normals, scan.poses[row])
    return cos_to_rays(n_x, n_z, sensor.ray_directions()[col])


def flagged(scan: Scan, nominal_z: np.ndarray, sensor: SensorSpec, k_sigma: float) -> np.ndarray:
    """(m, N) bool: valid points more than k_sigma·σ off the nominal depth `nominal_z` (m, N)
    along their column (inf where the nominal surface is not hit: flagged)."""
    with np.errstate(invalid="ignore"):
        dev = np.abs(scan.z_sensor - nominal_z)
        return scan.valid & ~(dev <= k_sigma * sigma_mm(scan, sensor))


def calls(points: np.ndarray, detector: Detector) -> list[np.ndarray]:
    """The calls among flagged (k, 3) points: index arrays of the clusters of at least
    `min_points` points (linked within `link_mm`)."""
    if len(points) < detector.min_points:
        return []
    pairs = cKDTree(points).query_pairs(detector.link_mm, output_type="ndarray")
    graph = coo_matrix(
        (np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(points), len(points))
    )
    _, label = connected_components(graph, directed=False)
    counts = np.bincount(label)
    return [np.flatnonzero(label == c) for c in np.flatnonzero(counts >= detector.min_points)]


def poses_over(defects: list[Defect], poses: np.ndarray, sensor: SensorSpec) -> np.ndarray:
    """Indices of the (m, 4, 4) poses whose laser plane and fan cross one of `defects`."""
    keep = np.zeros(len(poses), bool)
    rot_t = np.transpose(poses[:, :3, :3], (0, 2, 1))
    tan_half = np.tan(sensor.fov_rad / 2)
    z_lo, z_hi = sensor.depth_window_mm
    for d in defects:
        c = np.einsum("mij,mj->mi", rot_t, d.centre_mm - poses[:, :3, 3])  # in the sensor frame
        reach = d.radius_mm + 0.5
        keep |= (
            (np.abs(c[:, 1]) <= reach)
            & (c[:, 2] >= z_lo - reach)
            & (c[:, 2] <= z_hi + reach)
            & (np.abs(c[:, 0]) <= c[:, 2] * tan_half + reach)
        )
    return np.flatnonzero(keep)


def nominal_depth(
    scan: Scan,
    sensor: SensorSpec,
    plane_normal: np.ndarray,
    plane_point: np.ndarray,
    origin: np.ndarray,
) -> np.ndarray:
    """(m, N) the depth along each valid column of the NOMINAL surface under its hit: where
    the ray meets the plane of the nominal face (plane_normal, plane_point: (f, 3) each, not
    necessarily unit) that the hit face came from (`origin` (f',): `defects.inject`'s map).
    On a face no defect touched this is the true depth; on a refined one, the CAD's surface
    there. NaN where not valid or the ray runs along the plane."""
    valid = scan.valid
    face = origin[scan.face[valid]]
    rays = sensor.ray_directions()
    m_idx, n_idx = np.nonzero(valid)
    d = np.einsum("kij,kj->ki", scan.poses[m_idx, :3, :3], rays[n_idx])
    o = scan.poses[m_idx, :3, 3]
    n = plane_normal[face]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.einsum("ki,ki->k", n, plane_point[face] - o) / np.einsum("ki,ki->k", n, d)
    out = np.full(valid.shape, np.nan)
    out[valid] = t * rays[n_idx, 2]  # z_s = t * cos(the column's angle to the axis)
    return out


@dataclass(frozen=True)
class DefectTask:
    """One trial, picklable: the nominal mesh (vertices (v, 3), faces (f, 3), inspect_faces
    (f,) bool or None), the sensor, the plan's scanning poses (m, 4, 4), the defects placed
    and the call rule; `noise_seed` draws the trial's sensor noise; occluders: the fixtures
    (vertices (v, 3), faces (f, 3) each), which hide what they cover."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    inspect_faces: np.ndarray | None
    sensor: SensorSpec
    poses: np.ndarray
    defects: tuple[Defect, ...]
    detector: Detector
    noise_seed: int
    occluders: tuple[tuple[np.ndarray, np.ndarray], ...] = ()


def run_defect_trial(task: DefectTask) -> np.ndarray:
    """(d, 3) per defect of the trial: found (0/1), its flagged points and its valid points
    (the points that landed on it)."""
    out = np.zeros((len(task.defects), 3))
    defects = list(task.defects)
    idx = poses_over(defects, task.poses, task.sensor)
    if len(idx) == 0 or not defects:
        return out
    poses = task.poses[idx]
    mesh, origin = inject(trimesh.Trimesh(task.vertices, task.faces, process=False), defects)
    inspect = None if task.inspect_faces is None else task.inspect_faces[origin]
    part = Part(mesh, name=task.name, source=task.name, inspect_faces=inspect)
    part = part.among([trimesh.Trimesh(v, f, process=False) for v, f in task.occluders])
    profiler = LineProfilometer(part, task.sensor, seed=task.noise_seed)
    tri = task.vertices[task.faces]
    plane_normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    plane_point = tri[:, 0]
    link = task.detector.link_mm
    flagged_pts: list[list[np.ndarray]] = [[] for _ in defects]
    for _, scan in profiler.measure_in_chunks(poses, TRIAL_CHUNK_POSES):
        nominal_z = nominal_depth(scan, task.sensor, plane_normal, plane_point, origin)
        hit = flagged(scan, nominal_z, task.sensor, task.detector.k_sigma)
        points = scan.points_part[scan.valid]
        hit = hit[scan.valid]
        for j, d in enumerate(defects):
            near = np.linalg.norm(points - d.centre_mm, axis=1) <= d.radius_mm + link
            flagged_pts[j].append(points[near & hit])
            out[j, 2] += np.count_nonzero(d.displacement_mm(points[near]))
    for j, d in enumerate(defects):
        pts = np.concatenate(flagged_pts[j])
        on = d.displacement_mm(pts) != 0.0
        out[j, 0] = any(on[c].any() for c in calls(pts, task.detector))
        out[j, 1] = on.sum()
    return out


@dataclass(frozen=True)
class FalseCalls:
    """The calls on the defect-free part scanned with the plan: count over the scanned area
    (valid points x their cell, mm², an estimate) and the flagged points' share."""

    count: int
    flagged_points: int
    valid_points: int
    area_mm2: float

    @property
    def per_m2(self) -> float:
        return self.count / max(self.area_mm2 / 1e6, 1e-12)

    def to_json_dict(self) -> dict[str, float]:
        return {
            "count": self.count,
            "per_m2": self.per_m2,
            "area_mm2": self.area_mm2,
            "flagged_points": self.flagged_points,
            "valid_points": self.valid_points,
        }


def defect_tasks(
    part: Part,
    scan_spec: ScanSpec,
    traj: Trajectory,
    kind: str,
    sizes_mm: tuple[float, float],
    trials: int,
    per_trial: int = DEFECTS_PER_TRIAL,
    seed: int = 0,
    context: PlanContext | None = None,
    detector: Detector | None = None,
    surface: VisibleSurface | None = None,
) -> list[DefectTask]:
    """The `trials` tasks of a POD run: `per_trial` defects of `kind` each, far apart at
    random samples of the surface to inspect (the plan's region of interest), their sizes
    (depths) spread evenly in log over `sizes_mm` across all trials, in a seeded order.
    surface: the samples of the surface to inspect (`surface_samples`), if already drawn."""
    if trials < 1 or per_trial < 1:
        raise ValueError(f"--trials {trials}, --per-trial {per_trial}: must be >= 1")
    lo, hi = sizes_mm
    if not 0 < lo <= hi:
        raise ValueError(f"--sizes {lo:g}:{hi:g}: expected 0 < LO <= HI")
    if not traj.scanning.any():
        raise ValueError("trajectory has no scanning pose")
    sensor = scan_spec.sensor
    context = recorded(traj, scan_spec) if context is None else context
    part = part.with_roi(context.roi)
    if surface is None:
        surface = surface_samples(part, sensor, context, seed)
    if len(surface.points) == 0:
        raise ValueError(f"part {part.name} has no surface to inspect to put defects on")
    poses = traj.poses[traj.scanning]
    normals = outward_normals(part, surface.points, surface.faces, poses)
    detector = detector_for(traj, sensor) if detector is None else detector
    rng = np.random.default_rng(seed)
    sizes = np.exp(np.linspace(np.log(lo), np.log(hi), trials * per_trial))
    sizes = rng.permutation(sizes).reshape(trials, per_trial)
    gap = max(10.0, 4.0 * detector.link_mm)
    mesh = part.mesh
    fixtures = part_in_cell(context, part).occluders
    occluders = tuple((np.asarray(m.vertices), np.asarray(m.faces)) for m in fixtures)
    tasks = []
    for i in range(trials):
        trial_rng = np.random.default_rng([seed, i])
        placed = place(kind, sizes[i], surface.points, normals, trial_rng, gap)
        tasks.append(
            DefectTask(
                name=part.name,
                vertices=np.asarray(mesh.vertices),
                faces=np.asarray(mesh.faces),
                inspect_faces=part.inspect_faces,
                sensor=sensor,
                poses=poses,
                defects=tuple(placed),
                detector=detector,
                noise_seed=int(trial_rng.integers(2**63)),
                occluders=occluders,
            )
        )
    return tasks


def outward_normals(
    part: Part, points: np.ndarray, faces: np.ndarray, poses: np.ndarray
) -> np.ndarray:
    """(k, 3) the unit normals of the faces under (k, 3) surface points, each turned towards
    the nearest sensor position of the plan (CAD winding is not to be trusted)."""
    normals = np.asarray(part.mesh.face_normals)[faces]
    origins = poses[:, :3, 3]
    _, nearest = cKDTree(origins).query(points)
    flip = np.einsum("ki,ki->k", normals, origins[nearest] - points) < 0
    return np.where(flip[:, None], -normals, normals)


@dataclass(frozen=True)
class DefectRun:
    """A POD run: per defect (n,) its kind's size (depth, mm), found, flagged points on it
    and points that landed on it; the defects themselves; the fit and the call rule."""

    kind: str
    defects: list[Defect]
    hits: np.ndarray
    flagged_points: np.ndarray
    landed_points: np.ndarray
    fit: PodFit
    detector: Detector
    trials: int
    seed: int

    @property
    def sizes_mm(self) -> np.ndarray:
        return np.array([d.size_mm for d in self.defects])

    @property
    def seen_share(self) -> float:
        """The share of defects any valid point landed on."""
        return float((self.landed_points > 0).mean()) if len(self.defects) else 0.0

    def to_json_dict(self) -> dict[str, Any]:
        return {
            "type": self.kind,
            "size": "depth_mm",
            "shape": {"width_over_depth": ASPECT[self.kind]},
            "trials": self.trials,
            "seed": self.seed,
            "pod": self.fit.to_json_dict(),
            "seen_share": self.seen_share,
            "detector": self.detector.to_json_dict(),
            "defects": [
                {
                    **d.to_json_dict(),
                    "found": bool(h),
                    "flagged_points": int(f),
                    "landed_points": int(n),
                }
                for d, h, f, n in zip(
                    self.defects, self.hits, self.flagged_points, self.landed_points, strict=True
                )
            ],
        }


def defect_run(tasks: Sequence[DefectTask], run: TrialMap = map, seed: int = 0) -> DefectRun:  # type: ignore[assignment]
    """Run the trials with `run` (the builtin map, an executor's, a Dask client's) and fit."""
    if not tasks:
        raise ValueError("no trial to run")
    results = list(run(run_defect_trial, tasks))  # type: ignore[arg-type]
    defects = [d for t in tasks for d in t.defects]
    table = np.concatenate([r for r in results if len(r)]) if defects else np.zeros((0, 3))
    if not defects:
        raise ValueError("no defect could be placed on the surface to inspect")
    hits = table[:, 0] > 0
    sizes = np.array([d.size_mm for d in defects])
    return DefectRun(
        kind=defects[0].kind,
        defects=defects,
        hits=hits,
        flagged_points=table[:, 1],
        landed_points=table[:, 2],
        fit=fit_pod(sizes, hits),
        detector=tasks[0].detector,
        trials=len(tasks),
        seed=seed,
    )
