"""A car-door-like panel, 1440 × 1060 × 190 mm, outer skin up.

X runs front (−) to rear (+), Y from the sill (−) to the window frame (+). The skin is convex
with tumblehome above the belt line, a sharp-ish character line along X, a handle pocket and a
lowered window region with a slanted A-pillar edge.
"""

from __future__ import annotations

import numpy as np
import trimesh

from .heightfield import heightfield_solid

HALF_X_MM, HALF_Y_MM, HEIGHT_MM = 720.0, 530.0, 190.0
_SKIN_LOW_MM = 30.0  # the skin's lowest corner; the span above it is scaled to fit
_STEP_MM = 4.0

CREASE_Y_MM = 120.0
_CREASE_SLOPE = 0.1  # each side before scaling (x ~0.7): the normal turns by ~8°
_CREASE_SOFT_MM = 1.5

POCKET_CENTRE_MM = (480.0, 70.0)
POCKET_HALF_MM = (90.0, 30.0)
POCKET_DEPTH_MM = 20.0
_POCKET_CORNER_MM, _POCKET_WALL_MM = 22.0, 8.0

WINDOW_CENTRE_MM = (20.0, 365.0)
WINDOW_HALF_MM = (640.0, 125.0)
WINDOW_DEPTH_MM = 30.0
_WINDOW_CORNER_MM, _WINDOW_WALL_MM, _WINDOW_SHEAR = 45.0, 14.0, 0.45


def _axis(lo: float, hi: float, step: float, fine: list[tuple[float, float, float]]) -> np.ndarray:
    """Grid from lo to hi at `step`, replaced by (a, b, fine_step) inside each [a, b]."""
    pts = np.linspace(lo, hi, int(round((hi - lo) / step)) + 1)
    for a, b, _ in fine:
        pts = pts[(pts < a) | (pts > b)]
    parts = [pts] + [np.linspace(a, b, int(np.ceil((b - a) / s)) + 1) for a, b, s in fine]
    pts = np.unique(np.concatenate(parts))
    keep = np.concatenate([[True], np.diff(pts) > 0.4])
    return pts[keep]


def _rounded_rect_sd(x, y, half, corner):
    """Signed distance (mm, negative inside) to a rounded rectangle centred at the origin."""
    qx = np.abs(x) - (half[0] - corner)
    qy = np.abs(y) - (half[1] - corner)
    outside = np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0))
    return outside + np.minimum(np.maximum(qx, qy), 0.0) - corner


def _smoothstep(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def top_surface(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Shape of the skin before the recesses, in mm but before its span is scaled to fit."""
    u, v = x / HALF_X_MM, y / HALF_Y_MM
    z = -45.0 * u**2 - 70.0 * (v - 0.05) ** 2 - 8.0 * u**2 * v**2
    z -= 60.0 * (np.maximum(v - 0.4, 0.0) / 0.6) ** 2  # tumblehome above the belt
    z -= 25.0 * (np.maximum(-v - 0.6, 0.0) / 0.4) ** 2  # tuck-under at the sill
    z += 15.0 * u  # the rear stands a little prouder than the front
    d = y - CREASE_Y_MM
    z -= _CREASE_SLOPE * (np.sqrt(d**2 + _CREASE_SOFT_MM**2) - _CREASE_SOFT_MM)
    return z


def build() -> trimesh.Trimesh:
    px, py = POCKET_CENTRE_MM
    hx, hy = POCKET_HALF_MM
    wx, wy = WINDOW_CENTRE_MM
    whx, why = WINDOW_HALF_MM
    lean = _WINDOW_SHEAR * why  # how far the slanted window sides travel in x
    # Finer grid lines where the recess walls and the crease bend the skin sharply.
    xs = _axis(
        -HALF_X_MM,
        HALF_X_MM,
        _STEP_MM,
        [
            (wx - whx - lean - 5.0, wx - whx + lean + 5.0, 2.0),
            (px - hx - 10.0, px + hx + 10.0, 1.5),
            (wx + whx - lean - 5.0, HALF_X_MM, 2.0),
        ],
    )
    ys = _axis(
        -HALF_Y_MM,
        HALF_Y_MM,
        _STEP_MM,
        [
            (py - hy - 10.0, CREASE_Y_MM - 15.0, 1.5),
            (CREASE_Y_MM - 15.0, CREASE_Y_MM + 15.0, 1.0),
            (wy - why - 5.0, wy - why + _WINDOW_WALL_MM + 5.0, 1.5),
            (wy + why - _WINDOW_WALL_MM - 5.0, wy + why + 5.0, 1.5),
        ],
    )
    gx, gy = np.meshgrid(xs, ys)
    z = top_surface(gx, gy)
    z = _SKIN_LOW_MM + (HEIGHT_MM - _SKIN_LOW_MM) * (z - z.min()) / (z.max() - z.min())

    sd = _rounded_rect_sd(gx - px, gy - py, POCKET_HALF_MM, _POCKET_CORNER_MM)
    dish = 1.0 - 0.15 * ((gx - px) / hx) ** 2  # pocket floor slightly deeper in the middle
    z -= POCKET_DEPTH_MM * dish * _smoothstep(-sd / _POCKET_WALL_MM)

    sheared = gx - wx - _WINDOW_SHEAR * (gy - wy)  # A-pillar edge leans rearward going up
    sd = _rounded_rect_sd(sheared, gy - wy, WINDOW_HALF_MM, _WINDOW_CORNER_MM)
    z -= WINDOW_DEPTH_MM * _smoothstep(-sd / _WINDOW_WALL_MM)

    if z.min() < 10.0:
        raise RuntimeError(f"door skin dips to {z.min():.1f} mm")
    return heightfield_solid(xs, ys, z)


def skin_faces(mesh: trimesh.Trimesh) -> np.ndarray:
    """(f,) bool: the outer skin, the surface a door is inspected on. The solid's vertical
    sides and flat bottom only close the heightfield (a real door skin is a sheet, like
    vito_left_car_door); the skin is the heightfield's top, every face facing up."""
    return np.asarray(mesh.face_normals)[:, 2] > 1e-6
