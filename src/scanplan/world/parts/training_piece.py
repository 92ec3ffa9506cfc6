"""The training piece: 1050 × 150 × 50 mm, a profile z(x) of flats, ramps, steps and bumps.

The profile runs along X across the full width; one bump also tilts across Y so that roll
errors exist. Steps are exactly vertical (a repeated x in the grid).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import trimesh

from .heightfield import heightfield_solid

LENGTH_MM, WIDTH_MM, HEIGHT_MM = 1050.0, 150.0, 50.0
_FLAT_STEP_MM = 10.0  # planar zones are coarse
_CURVE_STEP_MM = 1.0  # curved zones are fine
_CROSS_GAIN = 0.4  # the cross-sloped bump is (1 ± 0.4) × its height at y = ±75 mm

# (kind, *args): flat(weight), ramp(angle_deg, dz), step(dz), arc(radius, dz), xarc(radius, dz)
# Flats share whatever length the other features leave; arcs are cylindrical caps/dips.
_FEATURES: tuple[tuple, ...] = (
    ("flat", 1.5),
    ("ramp", 10.0, 10.0),
    ("flat", 1.0),
    ("ramp", 20.0, -15.0),
    ("flat", 1.0),
    ("step", 25.0),
    ("flat", 1.0),
    ("step", -35.0),
    ("flat", 1.0),
    ("ramp", 30.0, 20.0),
    ("flat", 1.0),
    ("ramp", 45.0, -20.0),
    ("flat", 1.0),
    ("arc", 40.0, 20.0),
    ("flat", 1.0),
    ("ramp", 45.0, 25.0),
    ("flat", 1.0),
    ("arc", 60.0, -20.0),
    ("flat", 1.0),
    ("ramp", 30.0, -20.0),
    ("flat", 1.0),
    ("step", 10.0),
    ("flat", 1.0),
    ("arc", 100.0, 15.0),
    ("flat", 1.0),
    ("ramp", 20.0, 10.0),
    ("flat", 1.0),
    ("arc", 25.0, -10.0),
    ("flat", 1.0),
    ("step", -15.0),
    ("flat", 1.0),
    ("xarc", 50.0, 12.0),
    ("flat", 1.0),
    ("ramp", 10.0, 5.0),
    ("flat", 1.5),
)
_Z_START_MM = 30.0


def _feature_length(kind: str, args: Sequence[float]) -> float:
    if kind == "ramp":
        angle, dz = args
        return abs(dz) / np.tan(np.radians(angle))
    if kind in ("arc", "xarc"):
        radius, dz = args
        return 2.0 * np.sqrt(radius**2 - (radius - abs(dz)) ** 2)
    return 0.0


def profile() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, z, g) along the piece, x from 0 to 1050 mm: top z(x, y) = z + g · y.

    x repeats at each step (the two heights of the vertical face).
    """
    fixed = float(sum(_feature_length(k, a) for k, *a in _FEATURES))
    weights = sum(a[0] for k, *a in _FEATURES if k == "flat")
    per_weight = (LENGTH_MM - fixed) / weights
    if per_weight <= 10.0:
        raise RuntimeError("training-piece features do not fit its length")

    xs, zs, gs = [0.0], [_Z_START_MM], [0.0]
    for kind, *args in _FEATURES:
        x0, z0 = xs[-1], zs[-1]
        if kind == "step":
            xs.append(x0)
            zs.append(z0 + args[0])
            gs.append(0.0)
            continue
        length = per_weight * args[0] if kind == "flat" else _feature_length(kind, args)
        step = _CURVE_STEP_MM if kind in ("arc", "xarc") else _FLAT_STEP_MM
        u = np.linspace(0.0, length, max(2, int(np.ceil(length / step)) + 1))[1:]
        if kind == "flat":
            z, g = np.full_like(u, z0), np.zeros_like(u)
        elif kind == "ramp":
            z, g = z0 + args[1] * u / length, np.zeros_like(u)
        else:
            radius, dz = args
            cap = np.sqrt(np.maximum(radius**2 - (u - length / 2) ** 2, 0.0)) - (radius - abs(dz))
            cap[-1] = 0.0
            z = z0 + np.sign(dz) * cap
            g = np.sign(dz) * cap * _CROSS_GAIN / (WIDTH_MM / 2) if kind == "xarc" else 0 * u
        xs.extend(x0 + u)
        zs.extend(z)
        gs.extend(g)
    x = np.array(xs)
    x[-1] = LENGTH_MM  # absorb rounding
    return x, np.array(zs), np.array(gs)


def build() -> trimesh.Trimesh:
    x, z, g = profile()
    ys = np.linspace(-WIDTH_MM / 2, WIDTH_MM / 2, 31)
    z_top = z[None, :] + g[None, :] * ys[:, None]
    mesh = heightfield_solid(x - LENGTH_MM / 2, ys, z_top)
    top = mesh.bounds[1, 2]
    if not np.isclose(top, HEIGHT_MM) or z_top.min() < 14.0:
        raise RuntimeError(f"training-piece top spans {z_top.min():.1f}..{top:.1f} mm")
    return mesh
