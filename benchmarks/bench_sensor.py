"""Simulator throughput vs a bare Embree first-hit cast of the same rays, in one run.

Mesh: a wavy heightfield of >= 300k triangles. Prints medians over repeats and their ratios:
- full profile (4096 columns, occlusion, noise) vs the bare cast, single-pose calls;
- the same in one batch call (threads over the cores) vs single calls;
- the batch vs the bare cast of all its rays in one call.
Run: .venv/bin/python benchmarks/bench_sensor.py
"""

from __future__ import annotations

import statistics
import time

import numpy as np
import trimesh

from scanplan.part import part_from_mesh
from scanplan.sensor import LineProfilometer, SensorSpec
from scanplan.swaths import Swath


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


def median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    mesh = wavy_surface()
    part = part_from_mesh(mesh, "wavy")
    spec = SensorSpec()
    sensor = LineProfilometer(part, spec, seed=0)
    swath = Swath(0, np.array([-400.0, 0, 400]), np.array([400.0, 0, 400]),
                  np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))  # fmt: skip
    m = 64
    s = np.linspace(0, 600, m)
    poses = swath.poses(s, np.zeros(m), np.zeros(m))
    rays = spec.ray_directions()
    dirs = np.matmul(rays, poses[:, :3, :3].transpose(0, 2, 1))
    origins = np.broadcast_to(poses[:, None, :3, 3], dirs.shape)
    engine = part.ray_engine
    sensor.measure_many(poses[:4])  # warm up

    n_rays = m * len(rays)
    t_bare_single = median_time(
        lambda: [engine.first_hit_faces(origins[i], dirs[i]) for i in range(m)], 5
    )
    t_profile_single = median_time(lambda: [sensor.measure(p) for p in poses], 5)
    t_bare_batch = median_time(
        lambda: engine.first_hit_faces(origins.reshape(-1, 3), dirs.reshape(-1, 3)), 5
    )
    t_profile_batch = median_time(lambda: sensor.measure_many(poses), 5)
    valid = sensor.measure_many(poses).valid.mean()

    print(f"mesh: {len(mesh.faces)} triangles; {m} poses x {len(rays)} columns; "
          f"valid fraction {valid:.3f}")  # fmt: skip
    print(f"{'':34s}{'profiles/s':>12s}{'rays/s':>14s}")
    for label, t in [
        ("bare Embree first hit, per pose", t_bare_single),
        ("full profile, per pose", t_profile_single),
        ("bare Embree first hit, one call", t_bare_batch),
        ("full profile, batch", t_profile_batch),
    ]:
        print(f"{label:34s}{m / t:12.0f}{n_rays / t:14.3g}")
    print(f"ratio full profile / bare cast (single calls): {t_profile_single / t_bare_single:.2f}"
          "  (target <= 2.5)")  # fmt: skip
    print(f"ratio batch / single calls, per profile:       {t_profile_batch / t_profile_single:.2f}"
          "  (target <= 1)")  # fmt: skip
    print(f"ratio batch / bare cast in one call:           {t_profile_batch / t_bare_batch:.2f}")


if __name__ == "__main__":
    main()
