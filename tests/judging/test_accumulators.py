"""The coverage accumulator marks exactly the samples its definition names: those within the
radius of a point, on the sample's side (the brute-force answer); the real column pitch it
judges density with is the row formula's; a chunk's valid points are its masked ones."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from helpers import WD, straight
from scanplan.core.quantities import ScanSpec, dot_rows, norm_rows
from scanplan.judging.accumulators import SAME_SIDE_COS, Coverage, real_column_pitch
from scanplan.judging.chunks import valid_cells, valid_points
from scanplan.sensor.profilometer import LineProfilometer
from scanplan.world.part import part_from_mesh
from scanplan.world.surface import VisibleSurface

SENSOR = ScanSpec().sensor


def _sheet(rng: np.random.Generator, n: int, thickness: float):
    """Samples on both faces of a thin sheet, with their outward normals."""
    xy = rng.uniform(0, 40, (2 * n, 2))
    z = np.r_[np.zeros(n), np.full(n, -thickness)]
    normals = np.zeros((2 * n, 3))
    normals[:n, 2], normals[n:, 2] = 1.0, -1.0
    return np.column_stack([xy, z]), normals


def _scene(rng: np.random.Generator):
    """Samples on both faces of a thin sheet, and points over both faces, most of them under
    the sheet: the nearest point of a top sample is then often on the other side, and a
    farther one on its own must be found."""
    samples, sample_normals = _sheet(rng, 3000, 0.3)
    surface = VisibleSurface(samples, 1600.0, np.zeros(len(samples), np.int64))
    points, point_normals = _sheet(rng, 1500, 0.25)
    points[:, 0] /= 2  # over half the sheet
    points = np.r_[points[1200:], points[:300]]
    point_normals = np.r_[point_normals[1200:], point_normals[:300]]
    return surface, sample_normals, points, point_normals


def _brute(samples, sample_normals, points, point_normals, radius, usable=None):
    """Each sample with a (usable) point within the radius on its side, one by one."""
    pairs = cKDTree(samples).query_ball_point(points, radius)
    expected = np.zeros(len(samples), bool)
    for p, near in enumerate(pairs):
        if usable is not None and not usable[p]:
            continue
        near = np.asarray(near, np.int64)
        if point_normals is not None:
            near = near[sample_normals[near] @ point_normals[p] >= SAME_SIDE_COS]
        expected[near] = True
    return expected


def test_marks_the_samples_within_the_radius_on_their_side():
    surface, sample_normals, points, point_normals = _scene(np.random.default_rng(7))
    radius = 1.2
    coverage = Coverage(surface, ScanSpec(), 1, radius, radius, sample_normals)
    marked = np.zeros(len(surface.points), bool)
    marked[:50] = True  # marked before: stays marked
    coverage._mark(marked, points, point_normals, radius)

    expected = _brute(surface.points, sample_normals, points, point_normals, radius)
    expected[:50] = True
    assert marked.sum() > 500 and (~marked).sum() > 500  # neither everything nor nothing
    assert np.array_equal(marked, expected)


@pytest.mark.parametrize("plain", [True, False])
@pytest.mark.parametrize("qualifying", [0.3, 0.8])
@pytest.mark.parametrize("cover_held", [(1.6, 1.2), (1.2, 1.6)])
def test_a_chunk_covers_and_holds_in_spec_the_samples_its_definition_names(
    plain, qualifying, cover_held
):
    """A chunk's samples within the cover radius of any point are covered, those within the
    in-spec radius of a qualifying point on their side held in spec, whether most points
    qualify (one query of the chunk's tree, where the nearest point often does not qualify
    or lies on the other side) or few do (a tree of those)."""
    rng = np.random.default_rng(11)
    surface, sample_normals, points, point_normals = _scene(rng)
    cover, held = cover_held
    coverage = Coverage(surface, ScanSpec(), 1, cover, held, sample_normals, plain=plain)
    # Some samples in spec already, some covered already, from chunks before (in spec
    # and not covered only where the in-spec radius is the larger).
    before = np.zeros(len(surface.points), bool)
    before[0 if held <= cover else 40 : 80] = plain
    coverage.in_spec[:40] = True
    coverage.covered[:] = before
    qualifies = rng.random(len(points)) < qualifying
    tree = cKDTree(points)
    near = surface.near(points, max(cover, held))
    coverage._mark_chunk(points, point_normals, qualifies, near, lambda: tree)

    samples = surface.points
    in_spec = _brute(samples, sample_normals, points, point_normals, held, qualifies)
    in_spec[:40] = True
    assert in_spec.sum() > 200 and (~in_spec).sum() > 500
    assert np.array_equal(coverage.in_spec, in_spec)
    if plain:
        covered = _brute(samples, sample_normals, points, None, cover)
        covered |= before
        assert (covered & ~in_spec).any() and (in_spec & ~covered).any() == (held > cover)
        assert np.array_equal(coverage.covered, covered)
    else:
        assert not coverage.covered.any()


def _sphere_scan(points_per_profile: int, stride_poses: int = 40):
    """A sub-sampled fan looking at a sphere from random directions, at random rolls and
    stand-offs: points at every incidence, some columns missing the sphere."""
    rng = np.random.default_rng(3)
    fan = SENSOR.with_points(points_per_profile)
    part = part_from_mesh(trimesh.creation.icosphere(4, 60.0), "sphere")
    poses = np.zeros((stride_poses, 4, 4))
    for i, (look, up) in enumerate(
        zip(rng.normal(size=(stride_poses, 3)), rng.normal(size=(stride_poses, 3)), strict=True)
    ):
        z_s = -look / np.linalg.norm(look)
        x_s = np.cross(up, z_s)
        x_s /= np.linalg.norm(x_s)
        poses[i, :3, :3] = np.column_stack([x_s, np.cross(z_s, x_s), z_s])
        poses[i, :3, 3] = -z_s * (60.0 + WD + rng.uniform(-20, 20))
        poses[i, 3, 3] = 1.0
    return LineProfilometer(part, fan, seed=1).measure_many(poses)


def test_the_column_pitch_is_the_row_formula_on_every_point():
    """From the laser-plane components of the normals (flat (m, n) arrays): the pitch the
    point's ray, its distance and its normal projected into the laser plane give."""
    scan = _sphere_scan(96)
    assert scan.valid.sum() > 500 and not scan.valid.all()
    delta = SENSOR.line_width_mm / (SENSOR.points_per_profile - 1)
    ray = scan.points_part - scan.poses[:, None, :3, 3]
    rho = norm_rows(ray)
    y_s = scan.poses[:, None, :3, 1]
    normals = scan.normals_part
    n_plane = normals - dot_rows(normals, y_s)[..., None] * y_s
    cos_beta = np.abs(dot_rows(n_plane, ray)) / (norm_rows(n_plane) * rho)
    want = delta * scan.z_sensor**2 / (rho * WD * cos_beta)
    for cols in (slice(None), slice(None, None, 5)):
        got = real_column_pitch(scan, SENSOR, cols)
        assert np.array_equal(np.isnan(got), ~scan.valid[:, cols])
        np.testing.assert_allclose(got, want[:, cols], rtol=1e-12)
        assert (got[scan.valid[:, cols]] > 1.5 * delta).any()  # oblique points: wider


def test_a_plate_square_to_the_beam_has_the_column_pitch_scaled_by_depth(plate):
    """Flat, square to the beam: δ·z/W_d at every point (δ at the working distance)."""
    fan = SENSOR.without_noise().with_points(64)
    scan = LineProfilometer(plate, fan).measure_many(straight(np.arange(300, 320.0), 15.0).poses)
    pitch = real_column_pitch(scan, SENSOR)
    assert scan.valid.sum() > 500 and np.array_equal(np.isnan(pitch), ~scan.valid)
    delta = SENSOR.line_width_mm / (SENSOR.points_per_profile - 1)
    np.testing.assert_allclose(pitch[scan.valid], (delta * scan.z_sensor / WD)[scan.valid])


@pytest.mark.parametrize("stride", [1, 3])
def test_the_valid_points_of_a_chunk_are_its_masked_points_row_by_row(stride):
    scan = _sphere_scan(64, 12)
    valid = scan.valid[:, ::stride]
    row, col = valid_cells(scan, stride)
    np.testing.assert_array_equal(valid_points(scan, stride), scan.points_part[:, ::stride][valid])
    np.testing.assert_array_equal(row, np.nonzero(valid)[0])
    np.testing.assert_array_equal(col, np.nonzero(valid)[1] * stride)
    assert valid_points(scan, stride) is valid_points(scan, stride)  # gathered once
