"""The per-row products the scan quantities are made of: the same bits as numpy's reductions
(D, α and Δs, and with them every plan, must not move when they are made faster); the
incidence from the normals' laser-plane components."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from scanplan.core.quantities import (
    advance,
    cos_to_rays,
    dot_rows,
    mean_normal,
    norm_rows,
    normal_in_laser_plane,
)


def test_row_products_are_numpys_reductions_to_the_last_bit():
    rng = np.random.default_rng(7)
    a = rng.normal(size=(2000, 17, 3)) * 10.0 ** rng.uniform(-4, 4, (2000, 17, 3))
    b = rng.normal(size=(17, 3))
    a[rng.random((2000, 17)) < 0.1] = np.nan
    np.testing.assert_array_equal(dot_rows(a, b), np.sum(a * b, axis=-1))
    np.testing.assert_array_equal(norm_rows(a), np.linalg.norm(a, axis=-1))


def test_advance_counts_the_columns_valid_in_both_profiles():
    """Two profiles 2 mm apart along u, one 1 mm back on another column: the mean signed
    advance of the columns valid in both; none in common is NaN."""
    u = np.array([1.0, 0.0, 0.0])
    prev = np.zeros((1, 3, 3))
    nxt = prev.copy()
    nxt[0, :, 0] = [2.0, 2.0, -1.0]
    valid_prev = np.array([[True, True, True]])
    valid_next = np.array([[True, False, True]])
    nxt[0, 1] = np.nan  # an invalid column's point
    assert advance(prev, valid_prev, nxt, valid_next, u)[0] == 0.5
    assert np.isnan(advance(prev, valid_prev, nxt, ~valid_prev, u)[0])


def test_the_mean_normal_sums_the_columns_in_numpys_order_to_the_last_bit():
    rng = np.random.default_rng(5)
    normals = rng.normal(size=(40, 300, 3)) * 10.0 ** rng.uniform(-3, 3, (40, 300, 1))
    valid = rng.random((40, 300)) < 0.7
    valid[3] = False  # a profile with no valid point: NaN
    total = np.where(valid[..., None], normals, 0.0).sum(axis=-2)
    total[3] = np.nan
    want = total / np.linalg.norm(total, axis=-1, keepdims=True)
    np.testing.assert_array_equal(mean_normal(normals, valid), want)
    np.testing.assert_array_equal(mean_normal(normals[7], valid[7]), want[7])


def test_the_incidence_is_the_angle_between_the_ray_in_the_part_frame_and_the_normal():
    rng = np.random.default_rng(9)
    rotations = Rotation.random(50, random_state=rng).as_matrix()
    poses = np.zeros((50, 4, 4))
    poses[:, :3, :3], poses[:, 3, 3] = rotations, 1.0
    normals = rng.normal(size=(50, 8, 3))
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    rays = np.column_stack([rng.uniform(-0.5, 0.5, 8), np.zeros(8), np.ones(8)])
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    rays_part = np.einsum("mij,nj->mni", rotations, rays)
    n_x, n_z = normal_in_laser_plane(normals, poses[:, None])
    np.testing.assert_allclose(
        np.hypot(n_x, n_z),
        norm_rows(
            normals
            - dot_rows(normals, rotations[:, None, :, 1])[..., None] * rotations[:, None, :, 1]
        ),
        rtol=1e-12,
    )
    np.testing.assert_allclose(
        cos_to_rays(n_x, n_z, rays), np.abs(dot_rows(rays_part, normals)), rtol=1e-12, atol=1e-15
    )
