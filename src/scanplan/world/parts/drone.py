"""A drone-body-like shell, 350 × 95 × 65 mm (after the Parrot AR.Drone body).

An elongated rounded hull, nose at −X, a raised canopy set forward, side ridges, vent grooves
across the rear deck and a camera dome at the nose. Meshed on rings so the footprint is round.
"""

from __future__ import annotations

import numpy as np
import trimesh

from .heightfield import ring_solid

HALF_X_MM, HALF_Y_MM, HEIGHT_MM = 175.0, 47.5, 65.0
_N_OUTLINE, _N_RINGS = 480, 140
_SUPERELLIPSE = 2.6
_TAPER = 0.1  # the tail is a little wider than the nose


def outline() -> np.ndarray:
    """(480, 2) footprint outline, counter-clockwise, equal arc-length spacing, exact extents."""
    t = np.linspace(0.0, 2.0 * np.pi, 20001)
    e = 2.0 / _SUPERELLIPSE
    c, s = np.cos(t), np.sin(t)
    x = np.sign(c) * np.abs(c) ** e
    y = np.sign(s) * np.abs(s) ** e * (1.0 + _TAPER * x)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    at = np.linspace(0.0, arc[-1], _N_OUTLINE + 1)[:-1]
    x, y = np.interp(at, arc, x), np.interp(at, arc, y)
    x = (x - (x.max() + x.min()) / 2) * HALF_X_MM / ((x.max() - x.min()) / 2)
    y = (y - (y.max() + y.min()) / 2) * HALF_Y_MM / ((y.max() - y.min()) / 2)
    return np.column_stack([x, y])


def _smoothstep(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _height(rho, x, y):
    hull = 3.0 + 34.0 * np.sqrt(1.0 - np.minimum(rho, 1.0) ** 5)

    # canopy: a superellipse plateau set forward, domed on top
    rc = (np.abs((x + 15.0) / 110.0) ** 3 + np.abs(y / 34.0) ** 3) ** (1.0 / 3.0)
    canopy = 18.0 * _smoothstep((1.0 - rc) / 0.15) + 9.0 * np.maximum(1.0 - rc**2, 0.0)

    # ridges along the flanks, vents across the rear deck, camera dome at the nose
    flank = _smoothstep((110.0 - np.abs(x + 10.0)) / 20.0)
    ridges = 2.0 * flank * (np.exp(-(((np.abs(y) - 36.0) / 2.0) ** 2)))
    deck = _smoothstep((30.0 - np.abs(y)) / 6.0)
    vents = sum(np.exp(-(((x - xv) / 3.0) ** 2)) for xv in (112.0, 126.0, 140.0))
    grooves = -2.0 * deck * vents
    r_cam = np.hypot(x + 150.0, y) / 13.0
    camera = 7.0 * np.cos(np.minimum(r_cam, 1.0) * np.pi / 2) ** 2

    return hull + canopy + ridges + grooves + camera


def build() -> trimesh.Trimesh:
    t = np.linspace(0.0, 1.0, _N_RINGS)
    rho = 0.03 + 0.97 * (1.0 - (1.0 - t) ** 1.5)  # rings bunch up at the rounded rim
    mesh = ring_solid(outline(), rho, _height)
    mesh.apply_transform(np.diag([1.0, 1.0, HEIGHT_MM / mesh.bounds[1, 2], 1.0]))
    return mesh
