"""Measurement noise of a laser-triangulation profilometer, reproducible from a seed.

Two parts, both along the depth axis z_s:
- sensor noise, Gaussian with sigma(z, alpha) = sigma0 * (z / W_d)^2 / cos(alpha): triangulation
  depth error grows with the square of the range and with the spread of the laser spot on an
  inclined surface;
- speckle, spatially coherent: 3-D gradient (Perlin) noise evaluated at the surface point, so
  two overlapping profiles see the same speckle at the same place.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

# Cap 1/cos(alpha) so near-grazing points (which the incidence cutoff removes anyway) stay finite.
_MAX_INCIDENCE_GAIN = 10.0
# The speckle's standard deviation over a surface as a share of its amplitude (`perlin3` at
# 400 000 random points: 0.278).
SPECKLE_STD_RATIO = 0.28


@dataclass(frozen=True)
class NoiseModel:
    """sigma0_mm: Gaussian sigma at W_d on a surface facing the sensor.
    speckle_amplitude_mm: peak-ish amplitude of the coherent speckle (std ~ 0.3x this).
    speckle_scale_mm: correlation length of the speckle on the surface.
    seed: fixes the speckle pattern (the Gaussian part draws from the caller's Generator).
    """

    sigma0_mm: float = 0.004
    speckle_amplitude_mm: float = 0.015
    speckle_scale_mm: float = 0.5
    seed: int = 0

    def sigma_mm(
        self, z_mm: np.ndarray, cos_incidence: np.ndarray, working_distance_mm: float
    ) -> np.ndarray:
        gain = np.minimum(1.0 / np.maximum(cos_incidence, 1e-6), _MAX_INCIDENCE_GAIN)
        return self.sigma0_mm * (z_mm / working_distance_mm) ** 2 * gain

    def std_mm(
        self, z_mm: np.ndarray, cos_incidence: np.ndarray, working_distance_mm: float
    ) -> np.ndarray:
        """The standard deviation of `depth_noise_mm` at a point: the Gaussian part and the
        speckle's, independent."""
        sigma = self.sigma_mm(z_mm, cos_incidence, working_distance_mm)
        return np.hypot(sigma, SPECKLE_STD_RATIO * self.speckle_amplitude_mm)

    def depth_noise_mm(
        self,
        z_mm: np.ndarray,
        cos_incidence: np.ndarray,
        points_part: np.ndarray,
        working_distance_mm: float,
        rng: np.random.Generator,
    ) -> np.ndarray:
        """Noise to add to z_s for each point: Gaussian plus speckle. Shapes (n,), (n,), (n, 3)."""
        xyz = [points_part[:, k] for k in range(3)]
        return self.depth_noise_xyz_mm(z_mm, cos_incidence, xyz, working_distance_mm, rng)

    def depth_noise_xyz_mm(
        self,
        z_mm: np.ndarray,
        cos_incidence: np.ndarray,
        points_xyz: Sequence[np.ndarray],
        working_distance_mm: float,
        rng: np.random.Generator,
    ) -> np.ndarray:
        """`depth_noise_mm` with the points as three (n,) coordinate arrays."""
        sigma = self.sigma_mm(z_mm, cos_incidence, working_distance_mm)
        gaussian = rng.standard_normal(len(z_mm), dtype=np.float32) * sigma
        xyz = np.empty((3, len(z_mm)), dtype=np.float32)
        for k in range(3):
            np.divide(points_xyz[k], self.speckle_scale_mm, out=xyz[k], casting="same_kind")
        speckle = perlin3_components(xyz, seed=self.seed)
        speckle *= np.float32(self.speckle_amplitude_mm)
        return gaussian + speckle


@functools.lru_cache(maxsize=16)
def _lattice(seed: int) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """Perlin's hash and gradients as lookup tables.

    hash_xy: flat (257 * 257,), perm[perm[i] + j] at i * 257 + j (i, j in 0..256), so that the
    hash of lattice corner (i, j, k) is hash_xy[i * 257 + j] + k (perm: Perlin's doubled
    permutation table). gradient: six (511,) float32 tables, for hash h the gradient's x at h,
    x at h + 1, y at h, y at h + 1, z at h, z at h + 1 (h + 1: the corner one step up in z).
    """
    perm = np.random.default_rng(seed).permutation(256)
    perm = np.concatenate([perm, perm]).astype(np.intp)
    hash_xy = perm[perm[:257, None] + np.arange(257)].ravel()
    g = _GRADIENTS[perm % 12].astype(np.float32)
    gradient = tuple(
        np.ascontiguousarray(g[shift : len(g) - 1 + shift, axis])
        for axis in range(3)
        for shift in (0, 1)
    )
    return hash_xy, gradient


# The 12 edge-centre gradients of Ken Perlin's improved noise.
_GRADIENTS = np.array(
    [
        [1, 1, 0], [-1, 1, 0], [1, -1, 0], [-1, -1, 0],
        [1, 0, 1], [-1, 0, 1], [1, 0, -1], [-1, 0, -1],
        [0, 1, 1], [0, -1, 1], [0, 1, -1], [0, -1, -1],
    ],
    dtype=np.float64,
)  # fmt: skip


def perlin3(points: np.ndarray, seed: int = 0) -> np.ndarray:
    """Improved Perlin noise at scattered 3-D points. (n, 3) -> (n,) float64 in about [-1, 1].

    float32 inside: its 1e-5 relative error is far below the sensor resolution.
    """
    xyz = np.ascontiguousarray(np.asarray(points, dtype=np.float32).T)
    return perlin3_components(xyz, seed).astype(np.float64)


# Offsets of the lattice corners (cx, cy = 0, 1) in hash_xy, shaped (2, 1) over cy.
_CORNERS_Y = np.array([[0], [1]])


def perlin3_components(xyz: np.ndarray, seed: int = 0) -> np.ndarray:
    """`perlin3` on (3, n) float32 coordinates (one row per axis); returns (n,) float32.

    Vectorized over points (no maintained package evaluates Perlin/simplex noise at scattered
    points without a Python loop) and over the lattice corners: for each x corner one gather
    gives the hashes of both y corners, (2, n), and each gradient table serves both z corners.
    The corners are blended by trilinear interpolation with the fade weights. Temporaries stay
    small: arrays of 128 KiB and more come from mmap, and their page faults cost more than
    the arithmetic.
    """
    hash_xy, (gx0, gx1, gy0, gy1, gz0, gz1) = _lattice(seed)
    cell = np.floor(xyz)
    index = cell.astype(np.intp)
    index &= 255
    frac = xyz - cell
    frac1 = frac - 1
    fade = frac * 6  # 6f^5 - 15f^4 + 10f^3
    fade -= 15
    fade *= frac
    fade += 10
    fade *= frac
    fade *= frac
    fade *= frac
    base = index[0] * 257
    base += index[1]
    dy = np.stack([frac[1], frac1[1]])  # (2, n) over cy
    along_y = []
    for dx, cx in ((frac[0], 0), (frac1[0], 257)):
        h = hash_xy[base + (_CORNERS_Y + cx)]  # (2, n) over cy
        h += index[2]
        dot0 = gx0[h] * dx  # z corner 0
        dot0 += gy0[h] * dy
        dot0 += gz0[h] * frac[2]
        dot1 = gx1[h] * dx  # z corner 1
        dot1 += gy1[h] * dy
        dot1 += gz1[h] * frac1[2]
        # Blend along z, then y: a + f * (b - a).
        dot1 -= dot0
        dot1 *= fade[2]
        dot0 += dot1
        a, b = dot0[0], dot0[1] - dot0[0]
        b *= fade[1]
        a += b
        along_y.append(a)
    r, b = along_y[0], along_y[1] - along_y[0]
    b *= fade[0]
    r += b
    return r
