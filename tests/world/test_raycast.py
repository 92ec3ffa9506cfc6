"""The ray engine (Embree) against a plain numpy Möller–Trumbore reference."""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from scanplan.core.sensor_spec import SensorSpec
from scanplan.world.collision import CollisionChecker
from scanplan.world.part import Part, part_from_mesh


def _moller_trumbore(origins, dirs, triangles):
    """Plain numpy first hit, (n,) t and face, for checking Embree."""
    v0, v1, v2 = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    e1, e2 = v1 - v0, v2 - v0
    t_best = np.full(len(origins), np.inf)
    face = np.full(len(origins), -1)
    for i, (o, d) in enumerate(zip(origins, dirs, strict=True)):
        p = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, p)
        ok = np.abs(det) > 1e-12
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = o - v0
        u = np.einsum("ij,ij->i", s, p) * inv
        q = np.cross(s, e1)
        v = (q @ d) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9)
        if hit.any():
            k = np.argmin(np.where(hit, t, np.inf))
            t_best[i], face[i] = t[k], k
    return t_best, face


def test_embree_agrees_with_a_numpy_reference():
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=50.0)
    mesh.apply_translation((10, -5, 3))
    part = part_from_mesh(mesh)
    rng = np.random.default_rng(0)
    origins = rng.uniform(-150, 150, (300, 3))
    targets = rng.uniform(-40, 40, (300, 3)) + (10, -5, 3)
    dirs = targets - origins
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    dirs[:30] = -dirs[:30]  # some rays point away and miss
    t, face = part.ray_engine.first_hit(origins, dirs)
    t_ref, face_ref = _moller_trumbore(origins, dirs, mesh.triangles)
    assert np.array_equal(face >= 0, face_ref >= 0)
    hit = face_ref >= 0
    assert hit.sum() > 200
    assert np.allclose(t[hit], t_ref[hit], atol=1e-4)
    # Edge-sharing ties may pick either face; the hit point is what must agree.
    same = face[hit] == face_ref[hit]
    assert same.mean() > 0.97


def test_a_turned_part_answers_rays_like_a_part_built_turned_without_a_scene_of_its_own():
    """`Part.turned` (a view of the part): first hits, occlusion and the collision checks of
    the turned part agree with a part built from the turned mesh, and its engine asks the
    original's Embree scene (no second build: seconds on a large mesh)."""
    mesh = trimesh.creation.annulus(r_min=30.0, r_max=60.0, height=40.0, sections=48)
    mesh.apply_translation([300.0, -120.0, 20.0])  # off the origin: the offsets must agree
    base = part_from_mesh(mesh, "ring")
    R = np.eye(4)
    R[:3, :3] = Rotation.from_rotvec([0.9, -0.4, 0.2]).as_matrix()
    turned = base.turned(R)
    built = Part(turned.mesh.copy(), name="ring")
    assert turned.ray_engine._base is base.ray_engine  # type: ignore[attr-defined]
    rng = np.random.default_rng(3)
    lo, hi = built.bounds
    origins = rng.uniform(lo - 50.0, hi + 50.0, (4000, 3))
    dirs = rng.normal(size=(4000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    t1, f1 = turned.ray_engine.first_hit(origins, dirs)
    t2, f2 = built.ray_engine.first_hit(origins, dirs)
    assert (f2 >= 0).sum() > 300
    assert np.array_equal(f1 >= 0, f2 >= 0)
    both = (f1 >= 0) & (f2 >= 0)
    assert np.abs(t1[both] - t2[both]).max() < 1e-3
    assert np.allclose(turned.ray_engine.face_normals, built.ray_engine.face_normals, atol=1e-9)
    far = np.full(len(origins), 80.0)
    assert np.array_equal(
        turned.ray_engine.occluded(origins, dirs, far),
        built.ray_engine.occluded(origins, dirs, far),
    )
    sensor = SensorSpec()
    poses = np.tile(np.eye(4), (200, 1, 1))
    poses[:, :3, :3] = Rotation.random(200, random_state=4).as_matrix()
    poses[:, :3, 3] = rng.uniform(lo - 150.0, hi + 150.0, (200, 3))
    a = CollisionChecker(turned, sensor).check(poses, 20.0)
    b = CollisionChecker(built, sensor).check(poses, 20.0)
    assert 0 < a.colliding.sum() < len(poses)
    assert np.array_equal(a.colliding, b.colliding)
    assert np.allclose(a.distance_mm, b.distance_mm, atol=1e-6)
