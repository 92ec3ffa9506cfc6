"""Simulator throughput vs a bare Embree first-hit cast of the same rays, in one run.

Mesh: a wavy heightfield of >= 300k triangles. Prints the cost per profile (median over rounds
in which every variant runs once) and the ratios:
- full profile (4096 columns, occlusion, noise) vs the bare cast of the same rays, single-pose
  calls (both on one thread), and where it goes: Embree's own work (first hit and the camera's
  occlusion rays, cast alone), the rest (numpy, Python) and the depth noise (the same profiles
  measured without it);
- the same poses in one batch call (threads over the cores) vs single calls;
- the batch vs the bare cast of all its rays in one call (and the batch on one thread).
Run: .venv/bin/python benchmarks/bench_sensor.py
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import numpy as np
import trimesh

from scanplan.core.sensor_spec import SensorSpec
from scanplan.planning.swaths import Swath
from scanplan.sensor.profilometer import LineProfilometer, PointStatus
from scanplan.world.part import part_from_mesh


def wavy_surface(n: int = 400) -> trimesh.Trimesh:
    """(n-1)^2 * 2 triangles of a 1000 x 600 mm surface with 20 mm waves."""
    x, y = np.meshgrid(np.linspace(-500, 500, n), np.linspace(-300, 300, n), indexing="ij")
    z = 20 * np.sin(x / 60) * np.cos(y / 90) + 8 * np.sin(x / 17 + y / 23)
    vertices = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    faces = np.concatenate(
        [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    )
    return trimesh.Trimesh(vertices, faces, process=False)


def median_times(fns: dict[str, Callable[[], object]], repeats: int) -> dict[str, float]:
    """Median wall time of each fn; the fns take turns in every round, so a slow spell of a
    noisy machine hits them all alike."""
    times: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            start = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - start)
    return {name: statistics.median(t) for name, t in times.items()}


def main() -> None:
    mesh = wavy_surface()
    part = part_from_mesh(mesh, "wavy")
    spec = SensorSpec()
    sensor = LineProfilometer(part, spec, seed=0)
    serial = LineProfilometer(part, spec, seed=0, threads=1)
    quiet = LineProfilometer(part, spec.without_noise(), seed=0)
    swath = Swath(0, np.array([-400.0, 0, 400]), np.array([400.0, 0, 400]),
                  np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))  # fmt: skip
    m = 64
    s = np.linspace(0, 600, m)
    poses = swath.poses(s, np.zeros(m), np.zeros(m))
    rays = spec.ray_directions()
    # The same rays the simulator casts, in the part frame.
    dirs = np.matmul(rays, poses[:, :3, :3].transpose(0, 2, 1))
    origins = np.broadcast_to(poses[:, None, :3, 3], dirs.shape)
    engine = part.ray_engine
    sensor.measure_many(poses[:4])  # warm up

    # The Embree work inside a full profile, cast on its own: the first hit with distances and
    # the occlusion rays from the lit points towards the camera (the floor of the ratio).
    scan = sensor.measure_many(poses)
    cameras = poses[:, :3, :3] @ spec.camera_sensor + poses[:, :3, 3]
    laser, occlusion = [], []
    for i in range(m):
        laser.append(
            (
                np.ascontiguousarray(origins[i] - engine.offset, dtype=np.float32),
                np.ascontiguousarray(dirs[i], dtype=np.float32),
            )
        )
        # Lit points (the simulator casts for those of them that face the camera).
        seen = (scan.status[i] == PointStatus.VALID) | (scan.status[i] == PointStatus.SHADOWED)
        hit_points = (
            origins[i][seen] + dirs[i][seen] * scan.true_z_sensor[i][seen, None] / rays[seen, 2:3]
        )
        to_camera = cameras[i] - hit_points
        dist = np.linalg.norm(to_camera, axis=1)
        start = hit_points + scan.normals_part[i][seen] * 1e-2 - engine.offset
        occlusion.append(
            (
                np.ascontiguousarray(start, dtype=np.float32),
                np.ascontiguousarray(to_camera / dist[:, None], dtype=np.float32),
                (dist - 1e-2).astype(np.float32),
            )
        )

    def embree_work() -> None:
        for i in range(m):
            engine.first_hit_float32(*laser[i])
            engine.occluded_float32(*occlusion[i])

    t = median_times(
        {
            "embree_single": embree_work,
            "bare_single": lambda: [engine.first_hit_faces(origins[i], dirs[i]) for i in range(m)],
            "full_single": lambda: [sensor.measure(p) for p in poses],
            "quiet_single": lambda: [quiet.measure(p) for p in poses],
            "bare_batch": lambda: engine.first_hit_faces(
                origins.reshape(-1, 3), dirs.reshape(-1, 3)
            ),
            "full_batch": lambda: sensor.measure_many(poses),
            "full_batch_serial": lambda: serial.measure_many(poses),
        },
        repeats=7,
    )
    valid = sensor.measure_many(poses).valid.mean()

    print(f"mesh: {len(mesh.faces)} triangles; {m} poses x {len(rays)} columns; "
          f"valid fraction {valid:.3f}; occlusion + noise on")  # fmt: skip
    print("median of 7 rounds, per profile:")
    rows = [
        ("bare Embree first hit, one call per pose", "bare_single"),
        ("Embree work of a profile (first hit + occlusion)", "embree_single"),
        ("full profile, measure() per pose", "full_single"),
        ("the same without noise", "quiet_single"),
        ("bare Embree first hit, all poses in one call", "bare_batch"),
        (f"full profile, measure_many ({sensor.threads} threads)", "full_batch"),
        ("full profile, measure_many (1 thread)", "full_batch_serial"),
    ]
    for label, key in rows:
        print(f"  {label:48s}{t[key] / m * 1e3:8.3f} ms")
    single = t["full_single"] / t["bare_single"]
    batch = t["full_batch"] / t["full_single"]
    print(f"ratio full profile / bare cast, single calls:  {single:5.2f}  (target <= 2.0; "
          f"Embree work alone: {t['embree_single'] / t['bare_single']:.2f})")  # fmt: skip
    embree = t["embree_single"] / t["bare_single"]
    quiet_ratio = t["quiet_single"] / t["bare_single"]
    print(f"  of which Embree's work {embree:.2f}, the rest without noise "
          f"{quiet_ratio - embree:.2f}, the noise {single - quiet_ratio:.2f}")  # fmt: skip
    print(f"ratio batch / single calls, per profile:       {batch:5.2f}  (target <= 1)")
    print(f"ratio batch / bare cast in one call:           "
          f"{t['full_batch'] / t['bare_batch']:5.2f}  (batch on {sensor.threads} threads, "
          f"bare cast on 1)")  # fmt: skip
    print(f"ratio batch on 1 thread / bare cast in one call: "
          f"{t['full_batch_serial'] / t['bare_batch']:5.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
