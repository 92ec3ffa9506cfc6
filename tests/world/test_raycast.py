"""The ray engine (Embree) against a plain numpy Möller–Trumbore reference."""

from __future__ import annotations

import pickle

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


def _plate_lid_beside():
    """A 400 x 300 plate (top at z = 0), a lid 5 mm above its first 160 mm along x (x <
    -40) and a block beside it (x = 300) that hides nothing."""
    plate = trimesh.creation.box((400.0, 300.0, 10.0))
    plate.apply_translation((0, 0, -5.0))
    lid = trimesh.creation.box((160.0, 340.0, 10.0))
    lid.apply_translation((-120.0, 0, 10.0))
    beside = trimesh.creation.box((40.0, 40.0, 40.0))
    beside.apply_translation((300.0, 0, 20.0))
    return part_from_mesh(plate, "plate"), lid, beside


def test_an_occluder_hides_what_it_covers_and_is_never_hit():
    part, lid, _ = _plate_lid_beside()
    lidded = part.among([lid])
    x, y = np.meshgrid(np.arange(-195.0, 200.0, 10.0), np.arange(-145.0, 150.0, 10.0))
    above = np.stack([x.ravel(), y.ravel(), np.full(x.size, 100.0)], axis=1)
    down, up = np.tile([0.0, 0.0, -1.0], (len(above), 1)), np.tile([0.0, 0.0, 1.0], (len(above), 1))
    under = above[:, 0] < -40.0
    t, face = lidded.ray_engine.first_hit(above, down)
    # Under the lid a ray finds no point: neither the lid's nor the plate's it hides.
    assert under.any() and (face[under] == -1).all() and np.isinf(t[under]).all()
    assert (face[~under] >= 0).all() and np.allclose(t[~under], 100.0)
    # Its mesh alone (what the part is, whatever holds it) sees the whole plate, and so does
    # the part it was made from, whose Embree scene it shares.
    assert (lidded.ray_engine.alone.first_hit(above, down)[1] >= 0).all()
    assert (part.ray_engine.first_hit(above, down)[1] >= 0).all()
    assert lidded.ray_engine._scene is part.ray_engine._scene
    on_top = above - [0.0, 0.0, 99.95]
    far = np.full(len(on_top), 1e6)
    assert np.array_equal(lidded.ray_engine.occluded(on_top, up, far), under)
    assert not lidded.ray_engine.alone.occluded(on_top, up, far).any()
    # Only what lies within the distance asked blocks: the lid is 5 mm up.
    assert not lidded.ray_engine.occluded(on_top, up, np.full(len(on_top), 4.0)).any()
    assert part.among([]) is part and not part.occluders


def test_an_occluder_that_hides_nothing_changes_no_hit_bit_for_bit():
    part, _, beside = _plate_lid_beside()
    among = part.among([beside])
    rng = np.random.default_rng(5)
    origins = rng.uniform([-260.0, -200.0, 20.0], [260.0, 200.0, 450.0], (20_000, 3))
    targets = rng.uniform([-200.0, -150.0, -10.0], [200.0, 150.0, 0.0], (20_000, 3))
    # Rays in the planes of the plate's ends and sides, grazing its edges (a raster's first
    # and last profiles): the same hits, ties and all.
    origins[:2000, 0], targets[:2000, 0] = -200.0, -200.0
    origins[2000:4000, 1], targets[2000:4000, 1] = 150.0, 150.0
    dirs = targets - origins
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    t1, f1 = part.ray_engine.first_hit(origins, dirs)
    t2, f2 = among.ray_engine.first_hit(origins, dirs)
    assert (f1 >= 0).sum() > 10_000
    assert np.array_equal(f1, f2) and np.array_equal(t1, t2)
    R = np.eye(4)
    R[:3, :3] = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    turned_origins, turned_dirs = origins @ R[:3, :3].T, dirs @ R[:3, :3].T
    a = part.turned(R).ray_engine.first_hit(turned_origins, turned_dirs)
    b = among.turned(R).ray_engine.first_hit(turned_origins, turned_dirs)
    assert np.array_equal(a[1], b[1]) and np.array_equal(a[0], b[0])


def test_a_part_among_occluders_keeps_them_turned_pickled_and_restricted():
    part, lid, _ = _plate_lid_beside()
    lidded = part.among([lid])
    origins = np.array([[-100.0, 0.0, 100.0], [100.0, 0.0, 100.0]])  # under the lid, not
    down = np.tile([0.0, 0.0, -1.0], (2, 1))
    R = np.eye(4)
    R[:3, :3] = Rotation.from_rotvec([0.0, 0.7, 0.0]).as_matrix()
    turned_rays = origins @ R[:3, :3].T, down @ R[:3, :3].T
    turned_lid = lid.copy().apply_transform(R)
    # Turned in its cell, or put in the turned cell: the lid hides the same.
    for turned in (lidded.turned(R), part.turned(R).among([turned_lid])):
        assert turned.ray_engine.first_hit(*turned_rays)[1][0] == -1
        assert turned.ray_engine.alone.first_hit(*turned_rays)[1][0] >= 0
    engine = part.turned(R).ray_engine.among([(turned_lid.vertices, turned_lid.faces)])
    assert engine.first_hit(*turned_rays)[1][0] == -1
    for same in (pickle.loads(pickle.dumps(lidded)), lidded.with_roi("+z:30")):
        face = same.ray_engine.first_hit(origins, down)[1]
        assert face[0] == -1 and face[1] >= 0
