"""Closed solids from top surfaces: a rectilinear heightfield or a star-shaped ring grid.

Both close the top down to a flat bottom at z = 0 with vertical side walls, so the result is
one watertight, consistently wound solid with outward normals.
"""

from __future__ import annotations

import numpy as np
import trimesh


def heightfield_solid(xs, ys, z_top) -> trimesh.Trimesh:
    """Solid whose top is z_top over the grid xs × ys, bottom at z = 0, vertical sides.

    xs: (nx,) float, non-decreasing; ys: (ny,) float, non-decreasing.
    z_top: (ny, nx) float, z_top[j, i] is the height at (xs[i], ys[j]) (np.meshgrid order),
    every value > 0. A value repeated in xs or ys makes the cells between the two copies
    vertical, which is how sharp steps are written; the zero-area faces this leaves where the
    two heights agree are collapsed away.
    """
    xs = np.asarray(xs, dtype=np.float64)
    ys = np.asarray(ys, dtype=np.float64)
    z_top = np.asarray(z_top, dtype=np.float64)
    for name, axis in (("xs", xs), ("ys", ys)):
        if axis.ndim != 1 or np.unique(axis).size < 2:
            raise ValueError(f"{name} must be 1-D with at least 2 distinct values")
        if np.any(np.diff(axis) < 0) or not np.all(np.isfinite(axis)):
            raise ValueError(f"{name} must be finite and non-decreasing")
        if np.any((axis[2:] == axis[1:-1]) & (axis[1:-1] == axis[:-2])):
            raise ValueError(f"{name} repeats a value more than twice")
        if axis[0] == axis[1] or axis[-1] == axis[-2]:
            raise ValueError(f"{name} repeats its first or last value")
    nx, ny = xs.size, ys.size
    if z_top.shape != (ny, nx):
        raise ValueError(f"z_top has shape {z_top.shape}, expected (len(ys), len(xs)) = {(ny, nx)}")
    if not np.all(np.isfinite(z_top)) or np.any(z_top <= 0):
        raise ValueError("z_top must be finite and > 0 everywhere (the bottom is at z = 0)")

    gx, gy = np.meshgrid(xs, ys)
    top = np.column_stack([gx.ravel(), gy.ravel(), z_top.ravel()])
    idx = np.arange(nx * ny).reshape(ny, nx)
    v00, v01 = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    v10, v11 = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    top_faces = np.concatenate([np.column_stack([v00, v01, v11]), np.column_stack([v00, v11, v10])])

    # Perimeter counter-clockwise seen from +Z, each corner once.
    rim = np.concatenate([idx[0, :], idx[1:, -1], idx[-1, -2::-1], idx[-2:0:-1, 0]])
    return _close(top, top_faces, rim, centre_xy=((xs[0] + xs[-1]) / 2, (ys[0] + ys[-1]) / 2))


def ring_solid(boundary_xy, rho, height) -> trimesh.Trimesh:
    """Solid over a star-shaped footprint, top meshed on scaled copies of its outline.

    boundary_xy: (m, 2) float, the footprint outline counter-clockwise, star-shaped about the
    origin. rho: (k,) float, increasing in (0, 1], rho[-1] == 1: the rings are rho * outline.
    height: callable (rho (n,), x (n,), y (n,)) -> z (n,) > 0, the top surface.
    """
    boundary_xy = np.asarray(boundary_xy, dtype=np.float64)
    rho = np.asarray(rho, dtype=np.float64)
    if rho[-1] != 1.0 or rho[0] <= 0 or np.any(np.diff(rho) <= 0):
        raise ValueError("rho must increase within (0, 1] and end at 1")
    m, k = len(boundary_xy), len(rho)
    r_all = np.concatenate([[0.0], np.repeat(rho, m)])
    xy = np.vstack([[0.0, 0.0], (rho[:, None, None] * boundary_xy[None]).reshape(-1, 2)])
    z = np.asarray(height(r_all, xy[:, 0], xy[:, 1]), dtype=np.float64)
    if not np.all(np.isfinite(z)) or np.any(z <= 0):
        raise ValueError("height must be finite and > 0 everywhere")
    top = np.column_stack([xy, z])

    ring = 1 + np.arange(k * m).reshape(k, m)  # vertex 0 is the centre
    nxt = np.roll(ring, -1, axis=1)
    fan = np.column_stack([np.zeros(m, dtype=np.int64), ring[0], nxt[0]])
    a, b, c, d = ring[:-1].ravel(), ring[1:].ravel(), nxt[1:].ravel(), nxt[:-1].ravel()
    faces = np.concatenate([fan, np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    return _close(top, faces, ring[-1], centre_xy=(0.0, 0.0))


def _close(top, top_faces, rim, centre_xy) -> trimesh.Trimesh:
    """Add vertical walls below the counter-clockwise `rim` and a bottom fan at z = 0."""
    n_top, n_rim = len(top), len(rim)
    bottom = top[rim].copy()
    bottom[:, 2] = 0.0
    centre = np.array([[centre_xy[0], centre_xy[1], 0.0]])
    vertices = np.vstack([top, bottom, centre])

    t0, t1 = rim, np.roll(rim, -1)
    b0 = n_top + np.arange(n_rim)
    b1 = np.roll(b0, -1)
    c = np.full(n_rim, n_top + n_rim)
    lower = np.column_stack([b0, b1, t1])
    upper = np.column_stack([b0, t1, t0])
    extra = []
    # A vertical step in the rim (two rim vertices over one bottom point) is a segment of the
    # wall's edge below the taller vertex: split the wall triangle on that edge at the shorter
    # vertex, or the wall would meet the step in a T-junction.
    same_xy = np.all(top[t0, :2] == top[t1, :2], axis=1)
    for k in np.flatnonzero(same_xy):
        k1 = (k + 1) % n_rim
        lo, hi = (rim[k], rim[k1]) if top[rim[k], 2] < top[rim[k1], 2] else (rim[k1], rim[k])
        if top[lo, 2] == top[hi, 2]:
            continue
        if hi == rim[k1]:  # the quad after the step, triangle (b, t_next, hi)
            a, b_, _ = upper[k1]
            upper[k1] = (a, b_, lo)
            extra.append((lo, b_, hi))
        else:  # the quad before the step, triangle (b_prev, b, hi)
            a, b_, _ = lower[k - 1]
            lower[k - 1] = (a, b_, lo)
            extra.append((a, lo, hi))
    faces = np.concatenate(
        [top_faces, lower, upper, np.array(extra, dtype=np.int64).reshape(-1, 3)]
        + [np.column_stack([c, b1, b0])]
    )
    mesh = trimesh.Trimesh(vertices, faces, process=True)  # merges coincident vertices
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.remove_unreferenced_vertices()
    return mesh
