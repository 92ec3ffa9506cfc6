"""Simulated point clouds of a whole trajectory, with per-point error fields, as PLY."""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import trimesh

from scanplan.core.files import atomic_write_bytes
from scanplan.core.limits import MAX_CLOUD_POINTS, check_count
from scanplan.core.quantities import point_orientation_error
from scanplan.core.sensor_spec import SensorSpec
from scanplan.core.trajectory import Trajectory
from scanplan.sensor.profilometer import LineProfilometer
from scanplan.world.part import Part


@dataclass(frozen=True)
class PointCloud:
    """Valid points of a simulated scan.

    points_part: (k, 3) float64, mm.  distance_error_mm: (k,) z_s - W_d.
    orientation_error_rad: (k,) alpha_i.  profile: (k,) int index of the scanning pose.
    swath: (k,) int.
    """

    points_part: np.ndarray
    distance_error_mm: np.ndarray
    orientation_error_rad: np.ndarray
    profile: np.ndarray
    swath: np.ndarray


# A point of `write_ply`'s binary PLY: x, y, z float32, RGBA, two float32 and two int32
# fields (tests check it against a written file).
PLY_BYTES_PER_POINT = 32
PLY_HEADER_BYTES = 410


def ply_size_bytes(points: int) -> int:
    """About the size of the PLY `write_ply` writes for this many points."""
    return PLY_HEADER_BYTES + PLY_BYTES_PER_POINT * points


def simulate_cloud(
    part: Part,
    sensor: SensorSpec,
    traj: Trajectory,
    seed: int = 0,
    chunk_poses: int = 256,
    progress: Callable[[int, int], None] | None = None,
    max_points: int | None = None,
) -> PointCloud:
    """Measure every scanning pose and keep the valid points (chunked to bound memory); of a
    part with a region of interest, only the points on its faces. progress(done, total) is
    called after each chunk. max_points: keep a uniform random sample of at most this many
    valid points (seeded), in scan order; memory stays within about twice that."""
    profilometer = LineProfilometer(part, sensor, seed=seed)
    poses = traj.scan_poses
    # Every ray may give a point: the most the cloud may hold, before any is measured.
    most = len(poses) * sensor.points_per_profile
    check_count(
        most if max_points is None else min(most, max_points),
        MAX_CLOUD_POINTS,
        "points the cloud would hold in memory",
        "--max-points N keeps a sample",
    )
    swath_of_pose = traj.swath[traj.scanning]
    rng = np.random.default_rng(seed)
    fields = [*PointCloud.__dataclass_fields__, "key"]
    out: dict[str, list[np.ndarray]] = {k: [] for k in fields}
    held = 0
    for start, scan in profilometer.measure_in_chunks(poses, chunk_poses, progress):
        valid = scan.valid
        rows = np.nonzero(valid)[0]
        out["points_part"].append(scan.points_part[valid])
        out["distance_error_mm"].append(scan.z_sensor[valid] - sensor.working_distance_mm)
        alpha = point_orientation_error(scan.normals_part, scan.poses)
        out["orientation_error_rad"].append(alpha[valid])
        out["profile"].append(rows + start)
        out["swath"].append(swath_of_pose[rows + start])
        # A random key per point: the sample is the points with the smallest keys.
        out["key"].append(rng.random(len(rows)))
        held += len(rows)
        if max_points is not None and held > 2 * max_points:
            out, held = _smallest_keys(out, max_points), max_points
    if max_points is not None and held > max_points:
        out = _smallest_keys(out, max_points)
    return PointCloud(
        **{
            k: np.concatenate(v) if v else np.zeros((0, 3) if k == "points_part" else 0)
            for k, v in out.items()
            if k != "key"
        }
    )


def _smallest_keys(parts: dict[str, list[np.ndarray]], count: int) -> dict[str, list[np.ndarray]]:
    """The `count` points with the smallest keys, kept in scan order, as one chunk."""
    joined = {k: np.concatenate(v) for k, v in parts.items()}
    keep = np.sort(np.argpartition(joined["key"], count - 1)[:count]) if count else np.zeros(0, int)
    return {k: [v[keep]] for k, v in joined.items()}


def _colormap(values: np.ndarray, limit: float) -> np.ndarray:
    """RGBA uint8 from a diverging map, symmetric around 0 within +-limit."""
    from matplotlib import colormaps

    scaled = 0.5 + 0.5 * np.clip(values / max(limit, 1e-12), -1.0, 1.0)
    return (colormaps["coolwarm"](scaled) * 255).astype(np.uint8)


def write_ply(cloud: PointCloud, path: str | os.PathLike, color_limit_mm: float = 5.0) -> None:
    """Binary PLY: x, y, z, colour by distance error, and the scalar fields
    distance_error_mm, orientation_error_deg, profile, swath (CloudCompare/MeshLab read them)."""
    mesh = trimesh.Trimesh(
        vertices=cloud.points_part, faces=np.zeros((0, 3), dtype=np.int64), process=False
    )
    mesh.visual = trimesh.visual.ColorVisuals(
        mesh, vertex_colors=_colormap(cloud.distance_error_mm, color_limit_mm)
    )
    mesh.vertex_attributes["distance_error_mm"] = cloud.distance_error_mm.astype(np.float32)
    mesh.vertex_attributes["orientation_error_deg"] = np.degrees(
        cloud.orientation_error_rad
    ).astype(np.float32)
    mesh.vertex_attributes["profile"] = cloud.profile.astype(np.int32)
    mesh.vertex_attributes["swath"] = cloud.swath.astype(np.int32)
    data = trimesh.exchange.ply.export_ply(mesh, encoding="binary", include_attributes=True)
    atomic_write_bytes(path, data)
