"""The line profilometer simulated: a `SensorSpec` looking at a `Part`, measuring profiles
from many poses at once (`LineProfilometer.measure_many`), with the camera's line of sight,
the depth window, the grazing cut-off and seeded noise.
"""

from __future__ import annotations

import math
import os
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from enum import IntEnum
from functools import cached_property
from typing import Any

import numpy as np

from scanplan.core.limits import MAX_RAYS, check_count
from scanplan.core.sensor_spec import SensorSpec
from scanplan.world.part import Part


class PointStatus(IntEnum):
    """Why a pixel column returned (or did not return) a point."""

    VALID = 0
    NO_HIT = 1
    OUT_OF_RANGE = 2  # outside W_d +- Z_r/2
    GRAZING = 3  # laser incidence above the cutoff
    SHADOWED = 4  # the camera does not see the lit point (occluded or back-facing)


@dataclass(frozen=True)
class Scan:
    """Profiles measured from m poses with N pixel columns each.

    poses:        (m, 4, 4) float64, T_part_sensor.
    z_sensor:     (m, N) float64, measured depth along z_s (noise, quantization); NaN if invalid.
    x_sensor:     (m, N) float64, lateral position along x_s; NaN if invalid.
    points_part:  (m, N, 3) float64, measured points in the part frame; NaN if invalid.
    true_z_sensor:(m, N) float64, noise-free depth of the first hit; inf where no hit.
    normals_part: (m, N, 3) float64, face normals flipped towards the incoming ray (0 if no hit).
    face:         (m, N) int64, hit face index, -1 where no hit.
    status:       (m, N) uint8, `PointStatus` of each column.
    memo:         what those judging the scan derive from it once and share (its valid
                  points' k-d tree: `judging.accumulators.valid_points_tree`).
    """

    poses: np.ndarray
    z_sensor: np.ndarray
    x_sensor: np.ndarray
    points_part: np.ndarray
    true_z_sensor: np.ndarray
    normals_part: np.ndarray
    face: np.ndarray
    status: np.ndarray
    memo: dict[Any, Any] = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def valid(self) -> np.ndarray:
        """(m, N) bool."""
        return self.status == PointStatus.VALID

    def __len__(self) -> int:
        return len(self.poses)

    def on_faces(self, faces: np.ndarray) -> Scan:
        """Only the points on `faces` ((f,) bool: a region of interest); a column that hits
        another face reads as no hit, so every statistic of the scan is the region's."""
        off = (self.face >= 0) & ~faces[np.maximum(self.face, 0)]
        if not off.any():
            return self
        return Scan(
            poses=self.poses,
            z_sensor=np.where(off, np.nan, self.z_sensor),
            x_sensor=np.where(off, np.nan, self.x_sensor),
            points_part=np.where(off[..., None], np.nan, self.points_part),
            true_z_sensor=np.where(off, np.inf, self.true_z_sensor),
            normals_part=np.where(off[..., None], 0.0, self.normals_part),
            face=np.where(off, -1, self.face),
            status=np.where(off, PointStatus.NO_HIT, self.status).astype(self.status.dtype),
        )

    def profile(self, i: int) -> Profile:
        return Profile(
            T_part_sensor=self.poses[i],
            z_sensor=self.z_sensor[i],
            x_sensor=self.x_sensor[i],
            points_part=self.points_part[i],
            true_z_sensor=self.true_z_sensor[i],
            normals_part=self.normals_part[i],
            face=self.face[i],
            status=self.status[i],
        )


@dataclass(frozen=True)
class Profile:
    """One profile: the fields of `Scan` for a single pose, shapes (N,) / (N, 3) / (4, 4)."""

    T_part_sensor: np.ndarray
    z_sensor: np.ndarray
    x_sensor: np.ndarray
    points_part: np.ndarray
    true_z_sensor: np.ndarray
    normals_part: np.ndarray
    face: np.ndarray
    status: np.ndarray

    @cached_property
    def valid(self) -> np.ndarray:
        """(N,) bool; computed once (a training step reads it several times)."""
        return self.status == PointStatus.VALID


# At most this many rays of chunks measured ahead of the one `measure_in_chunks` hands out
# (about 90 bytes a ray): two chunks of 256 poses of up to 1024 columns.
AHEAD_RAYS = 2 * 256 * 1024


class LineProfilometer:
    """A SensorSpec looking at a Part.

    rng: the Generator the Gaussian noise draws from (pass `env.np_random` for seeded
    rollouts); by default one seeded with `seed`. threads: workers for large batches.
    """

    # Lift of occlusion-ray origins off the surface, mm: above float32 error of Embree at
    # part scale, far below any feature a profilometer resolves.
    _SURFACE_EPS_MM = 1e-2

    def __init__(
        self, part: Part, spec: SensorSpec, seed: int = 0, threads: int | None = None
    ) -> None:
        self.part = part
        self.spec = spec
        self.rng = np.random.default_rng(seed)
        self.threads = threads or os.cpu_count() or 1
        # ~100k rays a chunk: large enough to amortize Python, small enough to stay in cache.
        self.chunk_poses = max(1, 100_000 // spec.points_per_profile)
        self._rays_sensor = spec.ray_directions()
        # Per-spec constants of the fan, flat and contiguous (the rays have y_s = 0).
        self._ray_x = np.ascontiguousarray(self._rays_sensor[:, 0])
        self._ray_z = np.ascontiguousarray(self._rays_sensor[:, 2])  # cos to the laser axis
        self._ray_x_over_z = self._ray_x / self._ray_z
        self._cos_cutoff = math.cos(spec.incidence_cutoff_rad)
        self._camera_y = spec.camera_side * spec.baseline_mm
        self._block_poses = max(1, 4096 // spec.points_per_profile)

    def measure(self, T_part_sensor: np.ndarray, rng: np.random.Generator | None = None):
        """One profile from one pose."""
        return self.measure_many(np.asarray(T_part_sensor)[None], rng).profile(0)

    def measure_many(self, poses: np.ndarray, rng: np.random.Generator | None = None) -> Scan:
        """Profiles from (m, 4, 4) poses.

        Large batches are cut into chunks measured on a thread pool (Embree and numpy release
        the GIL); each chunk draws its Gaussian noise from a child seed taken from `rng` in
        order, so the result is reproducible whatever the thread timing.
        """
        poses = np.asarray(poses, dtype=np.float64)
        if poses.ndim != 3 or poses.shape[1:] != (4, 4):
            raise ValueError(f"poses must be (m, 4, 4), got {poses.shape}")
        rng = rng if rng is not None else self.rng
        m, n = len(poses), len(self._rays_sensor)
        scan = Scan(
            poses=poses,
            z_sensor=np.empty((m, n)),
            x_sensor=np.empty((m, n)),
            points_part=np.empty((m, n, 3)),
            true_z_sensor=np.empty((m, n)),
            normals_part=np.empty((m, n, 3)),
            face=np.empty((m, n), dtype=np.int64),
            status=np.empty((m, n), dtype=np.uint8),
        )
        if m <= self.chunk_poses:
            self._measure_chunk(scan, 0, m, rng)
            return scan
        starts = range(0, m, self.chunk_poses)
        seeds = rng.integers(0, 2**63 - 1, size=len(starts))
        with ThreadPoolExecutor(max_workers=self.threads) as pool:
            jobs = [
                pool.submit(
                    self._measure_chunk,
                    scan,
                    lo,
                    min(lo + self.chunk_poses, m),
                    np.random.default_rng(seed),
                )
                for lo, seed in zip(starts, seeds, strict=True)
            ]
            for job in jobs:
                job.result()
        return scan

    def measure_in_chunks(
        self,
        poses: np.ndarray,
        chunk_poses: int = 256,
        progress: Callable[[int, int], None] | None = None,
    ) -> Iterator[tuple[int, Scan]]:
        """(index of its first pose, Scan) for each chunk of `chunk_poses` poses in order, so
        a long trajectory is measured in bounded memory. Of a part with a region of interest,
        only the points on its faces (`Scan.on_faces`). progress(done, total) after each.
        The rays (poses x points per profile) are counted against `MAX_RAYS` first."""
        m = len(poses)
        check_count(
            m * self.spec.points_per_profile,
            MAX_RAYS,
            f"rays to cast ({m:,} poses x {self.spec.points_per_profile:,} points per profile)",
            "give fewer poses or --points",
        )
        starts = list(range(0, m, chunk_poses))
        # The next chunks are measured while the caller works on this one (Embree and numpy
        # release the GIL): judging a chunk costs about what measuring it does, more for
        # some chunks, less for others, so two are measured ahead where they are small (a
        # chunk that judges slowly then no longer holds up the measuring). One worker draws
        # the chunks' noise in order, so the scan is the same as measured in turn.
        depth = 2 if 2 * chunk_poses * self.spec.points_per_profile <= AHEAD_RAYS else 1
        with ThreadPoolExecutor(max_workers=1) as ahead:
            jobs = deque(
                ahead.submit(self._chunk_of, poses, lo, chunk_poses) for lo in starts[:depth]
            )
            try:
                for k, lo in enumerate(starts):
                    hi = min(m, lo + chunk_poses)
                    scan = jobs.popleft().result()
                    if k + depth < len(starts):
                        nxt = starts[k + depth]
                        jobs.append(ahead.submit(self._chunk_of, poses, nxt, chunk_poses))
                    yield lo, scan
                    if progress is not None:
                        progress(hi, m)
            finally:  # a caller that stops early does not wait for chunks it will not take
                for job in jobs:
                    job.cancel()

    def _chunk_of(self, poses: np.ndarray, lo: int, chunk_poses: int) -> Scan:
        """The scan of poses lo, lo+1, ... (`chunk_poses` of them at most), on the region of
        interest's faces."""
        scan = self.measure_many(poses[lo : lo + chunk_poses])
        if self.part.inspect_faces is not None:
            scan = scan.on_faces(self.part.inspect_faces)
        return scan

    def _measure_chunk(self, scan: Scan, lo: int, hi: int, rng: np.random.Generator) -> None:
        """Fill poses lo:hi of scan, drawing the Gaussian noise from rng in pose order.

        Measured in blocks of ~4k columns: numpy's temporaries then stay below 128 KiB, the
        size from which malloc maps fresh pages (page faults cost more than the arithmetic).
        """
        for start in range(lo, hi, self._block_poses):
            self._measure_block(scan, start, min(start + self._block_poses, hi), rng)

    def _measure_block(self, scan: Scan, lo: int, hi: int, rng: np.random.Generator) -> None:
        """All columns of m poses as (m, n) arrays, one array per xyz component: numpy is
        several times slower on (k, 3) rows than on flat arrays, and working on every column
        (misses included) costs less than gathering the hits first. Results are the same as
        computing on the hit columns only."""
        spec = self.spec
        poses = scan.poses[lo:hi]
        m, n = len(poses), len(self._rays_sensor)
        rot = poses[:, :3, :3]
        origin = poses[:, :3, 3]
        engine = self.part.ray_engine
        rx, cos_axis = self._ray_x, self._ray_z  # the sensor-frame rays have y = 0
        # (m, 1) columns of the pose, broadcast against the (n,) ray components.
        o = [origin[:, k, None] for k in range(3)]

        # Laser rays of all poses in one Embree call.
        d = [rot[:, k, 0, None] * rx + rot[:, k, 2, None] * cos_axis for k in range(3)]
        t32, face32 = engine.first_hit_float32(
            _pack_float32(o, engine.offset, (m, n)), _pack_float32(d, None, (m, n))
        )
        face = face32.astype(np.intp).reshape(m, n)
        hit = face >= 0
        t = t32.astype(np.float64).reshape(m, n)
        np.copyto(t, 0.0, where=~hit)  # any finite t; the misses are masked below
        true_z = t * cos_axis  # z_s = t * cos(angle of the column to the axis)
        dt = [c * t for c in d]
        p = [o[k] + dt[k] for k in range(3)]
        # Face normals; a miss (face -1) picks the table's trailing zero normal.
        normal = [table[face] for table in engine.face_normals_by_axis]
        # CAD exports often have inconsistent winding: face every normal towards its ray.
        cos_incidence = normal[0] * d[0]
        cos_incidence += normal[1] * d[1]
        cos_incidence += normal[2] * d[2]
        flip = cos_incidence > 0  # the normal points along the ray
        if flip.any():
            for c in normal:
                np.negative(c, out=c, where=flip)
        np.abs(cos_incidence, out=cos_incidence)

        z_lo, z_hi = spec.depth_window_mm
        in_window = (true_z >= z_lo) & (true_z <= z_hi) & hit
        lit = in_window & (cos_incidence > self._cos_cutoff)

        # Camera line of sight: a lit point must face the camera and see it unobstructed.
        valid_idx = self._seen_by_camera(rot, dt, p, normal, lit)
        pick = _picker(valid_idx, m * n)

        # Measured depth: true depth + noise, quantized to the Z resolution.
        z_valid = pick(true_z)
        if spec.noise is not None and len(valid_idx):
            z_valid = z_valid + spec.noise.depth_noise_xyz_mm(
                z_valid,
                pick(cos_incidence),
                [pick(c) for c in p],
                spec.working_distance_mm,
                rng,
            )
        if spec.z_resolution_mm > 0:
            z_valid = z_valid / spec.z_resolution_mm  # (z_valid may be a view of true_z)
            np.round(z_valid, out=z_valid)
            z_valid *= spec.z_resolution_mm
        z_meas = scan.z_sensor[lo:hi]
        if len(valid_idx) == m * n:
            z_meas[...] = z_valid.reshape(m, n)
        else:
            z_meas.fill(np.nan)
            z_meas.ravel()[valid_idx] = z_valid
        # The measured point lies on the same pixel column's ray, at the measured depth
        # (NaN wherever z_meas is).
        np.multiply(self._ray_x_over_z, z_meas, out=scan.x_sensor[lo:hi])
        scale = z_meas / cos_axis
        points_meas = scan.points_part[lo:hi]
        normals = scan.normals_part[lo:hi]
        for k in range(3):
            np.multiply(d[k], scale, out=points_meas[..., k])
            points_meas[..., k] += o[k]
            normals[..., k] = normal[k]
        true_z_out = scan.true_z_sensor[lo:hi]
        true_z_out.fill(np.inf)
        np.copyto(true_z_out, true_z, where=hit)
        scan.face[lo:hi] = face
        # NO_HIT 1, OUT_OF_RANGE 2, GRAZING 3, SHADOWED 4: one step per nested test passed.
        status = scan.status[lo:hi]
        np.add(hit.view(np.uint8), in_window.view(np.uint8), out=status)
        status += lit.view(np.uint8)
        status += np.uint8(PointStatus.NO_HIT)
        status.ravel()[valid_idx] = PointStatus.VALID

    def _seen_by_camera(
        self,
        rot: np.ndarray,
        beam: list[np.ndarray],
        points: list[np.ndarray],
        normal: list[np.ndarray],
        lit: np.ndarray,
    ) -> np.ndarray:
        """Flat indices into the (m, n) columns of the lit points that face the camera and see
        it unobstructed (an occlusion ray from just off the surface).

        rot: (m, 3, 3) the poses' rotations, sensor to part. beam, points, normal: x, y and z
        components, (m, n) each, in the part frame: the sensor origin to each hit (mm), the
        hits (mm), and their normals (turned to face the rays)."""
        engine = self.part.ray_engine
        camera_from_origin = rot[:, :, 1] * self._camera_y  # (m, 3); the camera is on y_s
        to_camera = [camera_from_origin[:, k, None] - beam[k] for k in range(3)]
        faces_camera = normal[0] * to_camera[0]
        faces_camera += normal[1] * to_camera[1]
        faces_camera += normal[2] * to_camera[2]
        cand = np.flatnonzero(lit & (faces_camera > 0))
        pick = _picker(cand, lit.size)
        to_cam = [pick(c) for c in to_camera]
        dist_camera = np.sqrt(to_cam[0] * to_cam[0] + to_cam[1] * to_cam[1] + to_cam[2] * to_cam[2])
        eps = self._SURFACE_EPS_MM
        k_cand = len(cand)
        start = np.empty((k_cand, 3), dtype=np.float32)
        unit = np.empty((k_cand, 3), dtype=np.float32)
        for k in range(3):
            lifted = pick(normal[k]) * eps
            lifted += pick(points[k])
            np.subtract(lifted, engine.offset[k], out=start[:, k], casting="same_kind")
            np.divide(to_cam[k], dist_camera, out=unit[:, k], casting="same_kind")
        dist_camera -= eps
        blocked = engine.occluded_float32(start, unit, dist_camera.astype(np.float32))
        return cand if not blocked.any() else cand[~blocked]


def _picker(idx: np.ndarray, size: int) -> Callable[[np.ndarray], np.ndarray]:
    """Flat gather of idx from (m, n) arrays; no gather when idx is every column."""
    if len(idx) == size:
        return lambda a: a.ravel()
    return lambda a: a.ravel()[idx]


def _pack_float32(
    components: list[np.ndarray], offset: np.ndarray | None, shape: tuple[int, ...]
) -> np.ndarray:
    """(..., 3) float32 rows for Embree from three arrays broadcastable to shape, minus offset."""
    out = np.empty((*shape, 3), dtype=np.float32)
    for k, c in enumerate(components):
        if offset is None:
            out[..., k] = c
        else:
            np.subtract(c, offset[k], out=out[..., k], casting="same_kind")
    return out.reshape(-1, 3)
