"""Perlin noise (noise.perlin3): bounded, seeded, and Ken Perlin's improved noise term by term."""

from __future__ import annotations

import numpy as np

from scanplan.core.noise import perlin3


def test_perlin_is_bounded_and_deterministic():
    pts = np.random.default_rng(0).uniform(-50, 50, (20000, 3))
    a, b, c = perlin3(pts, seed=1), perlin3(pts, seed=1), perlin3(pts, seed=2)
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)
    assert np.abs(a).max() <= 1.0
    assert 0.15 < a.std() < 0.4
    # Zero on the integer lattice, as Perlin noise is.
    assert np.allclose(perlin3(np.round(pts), seed=1), 0.0, atol=1e-6)


def _perlin_reference(point, seed):
    """Ken Perlin's improved noise at one point, written out corner by corner."""
    perm = np.random.default_rng(seed).permutation(256)
    perm = np.concatenate([perm, perm])
    gradients = np.array(
        [[1, 1, 0], [-1, 1, 0], [1, -1, 0], [-1, -1, 0], [1, 0, 1], [-1, 0, 1],
         [1, 0, -1], [-1, 0, -1], [0, 1, 1], [0, -1, 1], [0, 1, -1], [0, -1, -1]]
    )  # fmt: skip
    cell = np.floor(point)
    i, j, k = cell.astype(int) & 255
    frac = point - cell
    fade = frac**3 * (frac * (frac * 6 - 15) + 10)
    total = 0.0
    for cx in (0, 1):
        for cy in (0, 1):
            for cz in (0, 1):
                h = perm[perm[perm[i + cx] + j + cy] + k + cz]
                corner = np.array([cx, cy, cz])
                weight = np.prod(np.where(corner == 1, fade, 1 - fade))
                total += weight * gradients[h % 12] @ (frac - corner)
    return total


def test_perlin_matches_the_textbook_formula():
    pts = np.random.default_rng(3).uniform(-600, 600, (200, 3))
    fast = perlin3(pts, seed=4)
    slow = np.array([_perlin_reference(p.astype(np.float32).astype(np.float64), 4) for p in pts])
    assert np.allclose(fast, slow, atol=2e-6)
