"""How sure a plan is: its in-spec coverage over seeded perturbed parts (`robustness`).

A trial scans the part as built (the mesh warped and scaled, `perturb.Trial.as_built`) lying
where it really sits (the placement error), along the path the robot really flies (the
nominal poses with path noise), and judges the NOMINAL surface samples `evaluate` counts on.
The open-loop plan is replayed: nobody re-plans against the perturbed part. A closed-loop
plan's controller runs again on each perturbed part (`scanplan.jobs.trials`), judged here too.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import trimesh

from scanplan.core.context import PlanContext, recorded
from scanplan.core.quantities import ScanSpec, point_orientation_error
from scanplan.core.sensor_spec import SensorSpec
from scanplan.core.trajectory import Trajectory
from scanplan.judging.evaluation import coverage_of, scanning_steps, surface_samples
from scanplan.judging.summary import SurfaceState
from scanplan.sensor.perturb import Perturbation, Trial, bounds_centre
from scanplan.sensor.profilometer import LineProfilometer, Scan
from scanplan.world.cell import part_in_cell
from scanplan.world.part import Part
from scanplan.world.surface import VisibleSurface, oriented_normals

# (function, tasks) -> results in task order: the builtin map, an executor's, a Dask client's.
TrialMap = Callable[[Callable[["TrialTask"], np.ndarray], Sequence["TrialTask"]], Iterable[Any]]


@dataclass(frozen=True)
class TrialTask:
    """Everything one trial needs, picklable (no ray engine): sent to a worker process.

    vertices, normals: (v, 3) the nominal mesh's vertices and unit vertex normals; faces
    (f, 3); inspect_faces (f,) bool or None; poses (m, 4, 4) the scanning poses, has_prev
    (m,) bool; surface: the nominal samples judged, surface_normals their outward normals;
    occluders: the fixtures (vertices (v, 3), faces (f, 3) each), fixed in the nominal frame:
    the part moves among them, which hide it from the sensor."""

    name: str
    vertices: np.ndarray
    normals: np.ndarray
    faces: np.ndarray
    inspect_faces: np.ndarray | None
    scan_spec: ScanSpec
    sensor: SensorSpec  # the evaluated fan, perhaps sub-sampled
    poses: np.ndarray
    has_prev: np.ndarray
    surface: VisibleSurface
    surface_normals: np.ndarray  # (k, 3) the samples' outward normals
    model: Perturbation
    seed: int
    index: int
    chunk_poses: int
    occluders: tuple[tuple[np.ndarray, np.ndarray], ...] = ()


@dataclass(frozen=True)
class TrialWorld:
    """Trial `index`'s part: `part` the mesh as built (vertices `built`, the nominal faces
    in their order), lying at `T_part_placed` (4, 4) in the nominal frame."""

    trial: Trial
    part: Part
    built: np.ndarray
    T_part_placed: np.ndarray


def trial_world(task: TrialTask) -> TrialWorld:
    """The part of trial `task.index` as built and where it really sits."""
    trial = task.model.trial(task.seed, task.index)
    centre = bounds_centre(task.vertices)
    built = trial.as_built(task.vertices, task.normals, centre)
    mesh = trimesh.Trimesh(built, task.faces, process=False)  # same faces, same order
    part = Part(mesh, name=task.name, source=task.name, inspect_faces=task.inspect_faces)
    T_part_placed = trial.T_part_placed(centre)
    # The fixtures stay where the cell holds them (the nominal frame, where the part lies
    # at T_part_placed): in the part's own frame, where it is measured, they move back.
    T_back = np.linalg.inv(T_part_placed)
    fixtures = [
        trimesh.Trimesh(v @ T_back[:3, :3].T + T_back[:3, 3], f, process=False)
        for v, f in task.occluders
    ]
    return TrialWorld(trial, part.among(fixtures), built, T_part_placed)


def run_trial(task: TrialTask) -> np.ndarray:
    """(k,) bool: which nominal surface samples trial `task.index` holds in spec."""
    world = trial_world(task)
    trial, part, built = world.trial, world.part, world.built
    # The part sits at T_placed in the nominal frame and the robot flies the noisy path there.
    # Measuring the part in its own frame with the poses moved by the inverse placement is the
    # same scan, and its points come out in the nominal frame: the placement error undone
    # exactly. The warp and scale are undone per hit face (`_on_nominal`), so a point is
    # associated with the nominal sample nearest it (within the coverage radii) as in
    # `evaluate`, and it is the path, the placement and the part's shape that decide which
    # points there are and whether they are in spec.
    T_part_placed = world.T_part_placed
    poses = trial.path_poses(task.poses)
    if not np.array_equal(T_part_placed, np.eye(4)):
        poses = np.linalg.inv(T_part_placed) @ poses
    # The in-spec set alone: no plain coverage to mark (the same set, a third less work).
    coverage = coverage_of(
        task.surface, task.scan_spec, task.sensor, task.surface_normals, plain=False
    )
    # The sensor noise is the nominal evaluation's (same seed): trials differ by the
    # perturbation only.
    profiler = LineProfilometer(part, task.sensor, seed=task.seed)
    warped = not np.array_equal(built, task.vertices)
    for lo, scan in profiler.measure_in_chunks(poses, task.chunk_poses):
        ori = point_orientation_error(scan.normals_part, scan.poses)
        if warped:
            scan = replace(scan, points_part=_on_nominal(scan, task.vertices, built, task.faces))
        coverage.add(scan, ori, task.has_prev[lo : lo + len(scan)])
    return coverage.finish()[2].state == SurfaceState.IN_SPEC


def _on_nominal(
    scan: Scan, vertices: np.ndarray, built: np.ndarray, faces: np.ndarray
) -> np.ndarray:
    """(m, N, 3) the scan's points carried back from the as-built to the nominal surface: the
    same barycentric place on the same face, the depth noise kept. The in-spec radius is
    about a millimetre, the warp's size: left on the as-built surface, a point would miss
    the nominal sample it lies over."""
    points = scan.points_part.copy()
    valid = scan.valid
    tri = faces[scan.face[valid]]
    bary = trimesh.triangles.points_to_barycentric(built[tri], points[valid])
    bary = np.nan_to_num(bary)  # a degenerate face: its point stays where it is
    points[valid] += np.einsum("ki,kij->kj", bary, vertices[tri] - built[tri])
    return points


@dataclass(frozen=True)
class Robustness:
    """In-spec coverage over perturbed trials. per_trial: (n,) fractions; points_part (k, 3)
    the nominal surface samples and in_spec_share (k,) the fraction of trials each was in
    spec in (the fragility map)."""

    spec: str
    seed: int
    per_trial: np.ndarray
    points_part: np.ndarray
    in_spec_share: np.ndarray
    closed_loop: bool = False  # the plan's controller ran on each perturbed part (`trials`)

    @property
    def mean(self) -> float:
        return float(self.per_trial.mean())

    @property
    def p5(self) -> float:
        return float(np.percentile(self.per_trial, 5))

    @property
    def worst(self) -> float:
        return float(self.per_trial.min())

    def line(self, nominal: float | None = None) -> str:
        head = f"nominal {nominal:.1%}, " if nominal is not None else ""
        loop = "closed loop" if self.closed_loop else "open loop"
        return (
            f"robustness over {len(self.per_trial)} trials, {loop} ({self.spec}, seed "
            f"{self.seed}): "
            f"in-spec coverage {head}mean {self.mean:.1%}, p5 {self.p5:.1%}, "
            f"worst {self.worst:.1%} | {self.fragile_fraction:.1%} of the surface fragile "
            "(in spec in some trials, not all)"
        )

    @property
    def fragile_fraction(self) -> float:
        share = self.in_spec_share
        return float(((share > 0) & (share < 1)).mean()) if len(share) else 0.0

    def to_json_dict(self) -> dict[str, Any]:
        share = self.in_spec_share
        return {
            "trials": len(self.per_trial),
            "loop": "closed" if self.closed_loop else "open",
            "mean": self.mean,
            "p5": self.p5,
            "worst": self.worst,
            "per_trial": [float(v) for v in self.per_trial],
            "spec": self.spec,
            "seed": self.seed,
            "samples": len(share),
            "always_in_spec": float((share == 1).mean()) if len(share) else 0.0,
            "never_in_spec": float((share == 0).mean()) if len(share) else 0.0,
            "fragile": self.fragile_fraction,
        }

    def write_csv(self, path: Any) -> None:
        """The fragility map, one nominal sample a row: x_mm,y_mm,z_mm,in_spec_share."""
        table = np.column_stack([self.points_part, self.in_spec_share])
        np.savetxt(
            path,
            table,
            fmt="%.3f",
            delimiter=",",
            header="x_mm,y_mm,z_mm,in_spec_share",
            comments="",
        )


def trial_tasks(
    part: Part,
    scan_spec: ScanSpec,
    traj: Trajectory,
    model: Perturbation,
    trials: int,
    seed: int = 0,
    points_per_profile: int | None = None,
    context: PlanContext | None = None,
    chunk_poses: int = 256,
) -> list[TrialTask]:
    """The `trials` tasks of a robustness run, judged as `evaluate` with the same arguments
    judges the nominal scan (same samples, fan, sensor noise)."""
    if trials < 1:
        raise ValueError(f"--trials {trials}: must be >= 1")
    if not traj.scanning.any():
        raise ValueError("trajectory has no scanning pose")
    sensor = scan_spec.sensor
    spec = sensor.with_points(points_per_profile) if points_per_profile else sensor
    context = recorded(traj, scan_spec) if context is None else context
    part = part.with_roi(context.roi)
    surface = surface_samples(part, spec, context, seed)
    scan_idx, has_prev = scanning_steps(traj)
    occluders = tuple(
        (np.asarray(m.vertices), np.asarray(m.faces)) for m in part_in_cell(context, part).occluders
    )
    mesh = part.mesh
    surface_normals = oriented_normals(part)[surface.faces]
    return [
        TrialTask(
            name=part.name,
            vertices=np.asarray(mesh.vertices),
            normals=np.asarray(mesh.vertex_normals),
            faces=np.asarray(mesh.faces),
            inspect_faces=part.inspect_faces,
            scan_spec=scan_spec,
            sensor=spec,
            poses=traj.poses[scan_idx],
            has_prev=has_prev,
            surface=surface,
            surface_normals=surface_normals,
            model=model,
            seed=seed,
            index=i,
            chunk_poses=chunk_poses,
            occluders=occluders,
        )
        for i in range(trials)
    ]


def robustness(tasks: Sequence[TrialTask], run: TrialMap = map) -> Robustness:  # type: ignore[assignment]
    """Run the trials with `run` (the builtin map: here, one after another) and summarize."""
    if not tasks:
        raise ValueError("no trial to run")
    return summarize(tasks[0], list(run(run_trial, tasks)))


def summarize(
    first: TrialTask, results: Sequence[np.ndarray], closed_loop: bool = False
) -> Robustness:
    """The `Robustness` of trials' in-spec sets (`run_trial`'s, in task order), `first` the
    first trial's task (the model, seed and samples they share)."""
    in_spec = np.array(results, dtype=bool).reshape(len(results), -1)
    per_trial = in_spec.mean(axis=1) if in_spec.shape[1] else np.zeros(len(results))
    return Robustness(
        spec=first.model.text(),
        seed=first.seed,
        per_trial=per_trial,
        points_part=first.surface.points,
        in_spec_share=in_spec.mean(axis=0),
        closed_loop=closed_loop,
    )
