"""Built-in procedural parts: sizes, closed solids, determinism, the training piece's features."""

import numpy as np
import pytest

from scanplan.parts import PART_NAMES, build_part, door, drone, heightfield_solid, training_piece

EXTENTS_MM = {
    "training-piece": (1050.0, 150.0, 50.0),
    "door": (1440.0, 1060.0, 190.0),
    "drone": (350.0, 95.0, 65.0),
}
BUILDERS = {"training-piece": training_piece.build, "door": door.build, "drone": drone.build}
MAX_FACES = {"training-piece": 150_000, "door": 400_000, "drone": 150_000}


def test_part_names():
    assert PART_NAMES == ("training-piece", "door", "drone")


@pytest.mark.parametrize("name", PART_NAMES)
def test_part_is_a_closed_solid_of_the_stated_size(name):
    mesh = build_part(name)
    np.testing.assert_allclose(mesh.extents, EXTENTS_MM[name], rtol=0.02)
    assert mesh.bounds[0, 2] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(mesh.bounds[:, :2].mean(axis=0), 0.0, atol=1e-6)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.body_count == 1
    assert mesh.volume > 0.2 * np.prod(mesh.extents)  # outward normals, solid down to z = 0
    assert len(mesh.faces) < MAX_FACES[name]
    assert len(mesh.nondegenerate_faces()) == len(mesh.faces)


@pytest.mark.parametrize("name", PART_NAMES)
def test_part_is_deterministic_and_returned_as_a_copy(name):
    a = build_part(name)
    a.vertices[:, 2] += 100.0  # must not leak into the cache
    b, c = build_part(name), BUILDERS[name]()  # c bypasses the cache
    assert b is not c
    np.testing.assert_array_equal(b.vertices, c.vertices)
    np.testing.assert_array_equal(b.faces, c.faces)
    assert b.bounds[0, 2] == 0.0


@pytest.mark.parametrize("name", PART_NAMES)
def test_curved_top_is_finely_meshed(name):
    mesh = build_part(name)
    # pairs of upward faces that meet at an angle: the curved zones of the top surface
    up = mesh.face_normals[:, 2] > 0.05
    pairs = mesh.face_adjacency
    bend = up[pairs].all(axis=1) & (np.abs(mesh.face_adjacency_angles) > np.radians(0.5))
    faces = np.unique(pairs[bend])
    tri_xy = mesh.triangles[faces][:, :, :2]  # plan view: the pitch the sensor sweeps over
    longest_mm = np.linalg.norm(tri_xy - np.roll(tri_xy, 1, axis=1), axis=2).max(axis=1)
    assert len(faces) > 1000
    assert np.percentile(longest_mm, 90) < 6.0


def test_unknown_part_names_the_valid_ones():
    with pytest.raises(ValueError, match="unknown part 'bracket'") as info:
        build_part("bracket")
    for name in PART_NAMES:
        assert name in str(info.value)


def _top_tilts_deg(mesh):
    """Tilt from +Z of each upward face, and its area."""
    n = mesh.face_normals
    up = n[:, 2] > 0.05
    return np.degrees(np.arccos(np.clip(n[up, 2], -1, 1))), mesh.area_faces[up], n[up]


def test_training_piece_has_ramps_of_several_slopes():
    tilt, area, _ = _top_tilts_deg(build_part("training-piece"))
    bins = np.round(tilt * 2) / 2  # 0.5° bins
    planar = {b for b in np.unique(bins) if b >= 1.0 and area[bins == b].sum() > 2000.0}
    assert len(planar) >= 4
    for slope in (10.0, 20.0, 30.0, 45.0):
        ramp_area = area[np.abs(tilt - slope) < 0.05].sum()
        assert ramp_area > 150.0 * 5.0, f"no {slope}° ramp"
    flat_area = area[tilt < 0.01].sum()
    assert flat_area > 0.3 * 1050 * 150


def test_training_piece_volume_is_its_profile_times_width():
    x, z, _ = training_piece.profile()
    area_mm2 = np.sum(np.diff(x) * (z[1:] + z[:-1]) / 2)
    assert build_part("training-piece").volume == pytest.approx(150.0 * area_mm2, rel=1e-3)


def test_training_piece_has_vertical_steps_up_and_down_inside():
    mesh = build_part("training-piece")
    n, centre = mesh.face_normals, mesh.triangles_center
    inside = np.abs(centre[:, 0]) < 524.0
    for sign in (1, -1):
        riser = inside & (sign * n[:, 0] > 0.9999)
        assert mesh.area_faces[riser].sum() >= 150.0 * 10.0, f"no step facing {sign:+d}X"
        # a riser spans the full width of the piece
        assert np.ptp(centre[riser, 1]) > 140.0


def test_training_piece_top_heights_and_roll_feature():
    mesh = build_part("training-piece")
    _, _, n = _top_tilts_deg(mesh)
    top = mesh.vertices[mesh.vertices[:, 2] > 1.0]
    assert top[:, 2].min() == pytest.approx(15.0, abs=1.0)
    assert top[:, 2].max() == pytest.approx(50.0)
    # the cross-sloped bump: upward faces that lean sideways (roll), by more than a degree
    roll = np.degrees(np.arctan2(np.abs(n[:, 1]), n[:, 2]))
    assert roll.max() > 1.0
    assert roll.max() < 15.0


def test_door_has_its_features():
    mesh = build_part("door")
    v = mesh.vertices
    top = v[v[:, 2] > 1.0]
    # convex bulge: the middle stands well above the edges
    centre = top[np.hypot(top[:, 0], top[:, 1] - 50.0) < 60.0, 2].mean()
    edge = top[np.abs(top[:, 0]) > 715.0, 2].mean()
    assert centre - edge > 50.0
    # handle pocket ~20 mm deep against the skin around it
    pocket = top[(np.abs(top[:, 0] - 480.0) < 40.0) & (np.abs(top[:, 1] - 70.0) < 10.0), 2]
    around = top[(np.abs(top[:, 0] - 480.0) < 40.0) & (np.abs(top[:, 1] - 70.0 + 50.0) < 3.0), 2]
    assert around.mean() - pocket.mean() == pytest.approx(20.0, abs=6.0)
    # character line: the slope dz/dy jumps across y = 120 mm
    col = top[np.abs(top[:, 0] - 0.0) < 1e-6]
    col = col[np.argsort(col[:, 1])]
    dzdy = np.diff(col[:, 2]) / np.diff(col[:, 1])
    mid = (col[1:, 1] + col[:-1, 1]) / 2
    below = dzdy[(mid > 110.0) & (mid < 118.0)].mean()
    above = dzdy[(mid > 122.0) & (mid < 130.0)].mean()
    assert np.degrees(np.arctan(below) - np.arctan(above)) > 5.0


def test_drone_has_a_raised_canopy_on_a_rounded_hull():
    mesh = build_part("drone")
    v = mesh.vertices
    top = v[v[:, 2] > 0.5]
    assert top[np.hypot(top[:, 0] + 15.0, top[:, 1]) < 10.0, 2].min() > 60.0
    assert top[np.abs(top[:, 0] - 150.0) < 3.0, 2].max() < 45.0
    # round footprint: no vertex near the bounding box corners
    assert not np.any((np.abs(v[:, 0]) > 150.0) & (np.abs(v[:, 1]) > 40.0))


def test_heightfield_solid_tilted_plate():
    xs, ys = np.linspace(-50, 50, 11), np.linspace(-20, 20, 5)
    z = 30.0 + 0.1 * xs[None, :] + 0.0 * ys[:, None]
    mesh = heightfield_solid(xs, ys, z)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume == pytest.approx(100.0 * 40.0 * 30.0)
    up = mesh.face_normals[mesh.face_normals[:, 2] > 0.05]
    np.testing.assert_allclose(
        up, np.tile([-np.sin(np.arctan(0.1)), 0, np.cos(np.arctan(0.1))], (len(up), 1)), atol=1e-12
    )


def test_heightfield_solid_step_from_a_repeated_x():
    xs, ys = np.array([0.0, 10.0, 10.0, 20.0]), np.array([0.0, 5.0, 10.0])
    z = np.tile([5.0, 5.0, 8.0, 8.0], (3, 1))
    mesh = heightfield_solid(xs, ys, z)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume == pytest.approx(10 * 10 * 5 + 10 * 10 * 8)
    riser = mesh.face_normals[:, 0] < -0.999
    assert mesh.area_faces[riser & (mesh.triangles_center[:, 0] > 1)].sum() == pytest.approx(30.0)


@pytest.mark.parametrize(
    ("xs", "ys", "z", "match"),
    [
        ([0, 1], [0, 1], np.ones((2, 3)), "shape"),
        ([0, 1], [0, 1], np.zeros((2, 2)), "> 0"),
        ([1, 0], [0, 1], np.ones((2, 2)), "non-decreasing"),
        ([0, 1, 1, 1, 2], [0, 1], np.ones((2, 5)), "more than twice"),
    ],
)
def test_heightfield_solid_rejects_bad_input(xs, ys, z, match):
    with pytest.raises(ValueError, match=match):
        heightfield_solid(xs, ys, z)
