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
        x, y, z = (
            np.divide(
                c, self.speckle_scale_mm, out=np.empty(len(c), np.float32), casting="same_kind"
            )
            for c in points_xyz
        )
        speckle = perlin3_xyz(x, y, z, seed=self.seed)
        speckle *= np.float32(self.speckle_amplitude_mm)
        return gaussian + speckle


@functools.lru_cache(maxsize=16)
def _lattice(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Perlin's doubled permutation table and the gradient components its hashes select."""
    perm = np.random.default_rng(seed).permutation(256)
    perm = np.concatenate([perm, perm]).astype(np.intp)
    gradient = _GRADIENTS[perm % 12].astype(np.float32)
    gx, gy, gz = (np.ascontiguousarray(gradient[:, i]) for i in range(3))
    return perm, gx, gy, gz


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
    p = np.asarray(points, dtype=np.float32)
    x, y, z = (np.ascontiguousarray(p[:, k]) for k in range(3))
    return perlin3_xyz(x, y, z, seed).astype(np.float64)


def perlin3_xyz(x: np.ndarray, y: np.ndarray, z: np.ndarray, seed: int = 0) -> np.ndarray:
    """`perlin3` on three (n,) float32 coordinate arrays; returns (n,) float32.

    Vectorized over points (no maintained package evaluates Perlin/simplex noise at scattered
    points without a Python loop); the loop runs over the 8 lattice corners only, and the
    corners are blended by trilinear interpolation with the fade weights.
    """
    perm, gx, gy, gz = _lattice(seed)
    cells = [np.floor(c) for c in (x, y, z)]
    i0, j0, k0 = (c.astype(np.intp) & 255 for c in cells)
    x0, y0, z0 = x - cells[0], y - cells[1], z - cells[2]
    x1, y1, z1 = x0 - 1, y0 - 1, z0 - 1
    fx, fy, fz = (c * c * c * (c * (c * 6 - 15) + 10) for c in (x0, y0, z0))
    dots = []
    for cx, dx in ((0, x0), (1, x1)):
        hx = perm[i0 + cx] + j0
        for cy, dy in ((0, y0), (1, y1)):
            hy = perm[hx + cy] + k0
            for cz, dz in ((0, z0), (1, z1)):
                h = hy + 1 if cz else hy
                dot = gx[h] * dx
                dot += gy[h] * dy
                dot += gz[h] * dz
                dots.append(dot)
    # Blend along z, then y, then x: a + f * (b - a).
    for f in (fz, fy, fx):
        dots = [a + f * (b - a) for a, b in zip(dots[::2], dots[1::2], strict=True)]
    return dots[0]
