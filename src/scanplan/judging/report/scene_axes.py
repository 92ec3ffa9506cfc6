"""The external axes in the 3-D scene (`scene`): what moves with them at each pose drawn
(the turntable's pointer, the track's carriage, drawn with the arm and stepped by its
slider) and what stands still in the part frame (the turntable's disk, the track's rail);
and the closed cylinders the arm and they are drawn with.
"""

from __future__ import annotations

import numpy as np

from scanplan.robot.axes import ExternalAxes

CAPSULE_SIDES = 12
# External axes: the turntable's pointer (from its axis to its rim, towards the arm: it
# turns with the slider) and the track's carriage under the arm (rides with the slider).
POINTER_RADIUS_MM = 12.0
CARRIAGE_RADIUS_MM = 80.0
CARRIAGE_HALF_MM = 200.0
POSITIONER_COLOUR = "#4a6fa5"


def capsule_mesh(ends: np.ndarray, radii: np.ndarray, sides: int = CAPSULE_SIDES):
    """(vertices (c·(2·sides+2), 3), faces (c·4·sides, 3)) of closed cylinders round the
    segments `ends` (c, 2, 3) with `radii` (c,): the capsules drawn without their caps'
    domes (a joint's neighbour covers them)."""
    a, b = ends[:, 0], ends[:, 1]
    axis = b - a
    length = np.linalg.norm(axis, axis=1, keepdims=True)
    d = np.where(length > 1e-9, axis / np.maximum(length, 1e-9), [0.0, 0.0, 1.0])
    helper = np.where(np.abs(d[:, [0]]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    u = np.cross(d, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(d, u)
    t = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = np.cos(t)[None, :, None] * u[:, None] + np.sin(t)[None, :, None] * w[:, None]
    ring *= radii[:, None, None]
    # Per capsule: ring at a, ring at b, then the two cap centres.
    verts = np.concatenate([a[:, None] + ring, b[:, None] + ring, a[:, None], b[:, None]], axis=1)
    j = np.arange(sides)
    k = (j + 1) % sides
    ca, cb = 2 * sides, 2 * sides + 1
    local = np.concatenate(
        [
            np.stack([j, k, sides + k], axis=1),
            np.stack([j, sides + k, sides + j], axis=1),
            np.stack([np.full(sides, ca), k, j], axis=1),
            np.stack([np.full(sides, cb), sides + j, sides + k], axis=1),
        ]
    )
    per = verts.shape[1]
    faces = local[None] + (np.arange(len(ends)) * per)[:, None, None]
    return verts.reshape(-1, 3), faces.reshape(-1, 3)


def axis_capsules(axes: ExternalAxes, T_part_base: np.ndarray) -> tuple[np.ndarray, list]:
    """((m, j, 2, 3) segment ends in the part frame, (j,) radii) of what moves with the
    external axes at the poses drawn (the arm's base at `T_part_base` (m, 4, 4)): the
    turntable's pointer from its axis towards the arm, the track's carriage under it."""
    base = T_part_base[:, :3, 3]
    out, radii = [], []
    if (t := axes.turntable) is not None and t.axis_point_mm is not None:
        centre = np.broadcast_to(np.asarray(t.axis_point_mm, dtype=np.float64), base.shape)
        towards = base - centre
        towards[:, 2] = 0.0
        towards /= np.maximum(np.linalg.norm(towards, axis=1, keepdims=True), 1e-9)
        rim = centre + t.radius_mm * towards
        out.append(np.stack([centre, rim], axis=1) + [0.0, 0.0, POINTER_RADIUS_MM])
        radii.append(POINTER_RADIUS_MM)
    if (k := axes.track) is not None and k.direction is not None:
        d = np.einsum("mij,j->mi", T_part_base[:, :3, :3], np.asarray(k.direction, float))
        out.append(np.stack([base - CARRIAGE_HALF_MM * d, base + CARRIAGE_HALF_MM * d], axis=1))
        radii.append(CARRIAGE_RADIUS_MM)
    return np.stack(out, axis=1), radii


def axes_traces(
    axes: ExternalAxes | None, shown_axes: np.ndarray | None, T_base_part: np.ndarray
) -> list:
    """What of the external `axes` stands still in the part frame (the part at
    `T_base_part` with every axis at 0; `shown_axes` their values at the poses drawn): the
    turntable's disk under the part, the track's rail (its whole travel, where the arm
    rides)."""
    if axes is None:
        return []
    traces = []
    if (t := axes.turntable) is not None and t.axis_point_mm is not None:
        top = np.asarray(t.axis_point_mm, dtype=np.float64)
        disk = np.array([[top - [0.0, 0.0, 40.0], top]])
        v, f = capsule_mesh(disk, np.array([t.radius_mm]), sides=48)
        traces.append(_solid(v, f, f"turntable (r {t.radius_mm:g} mm)", POSITIONER_COLOUR, 0.5))
    if (k := axes.track) is not None and k.direction is not None:
        lo, hi = axes.limits[-1]
        values = np.zeros((2, len(axes.names)))
        values[:, -1] = lo, hi
        if shown_axes is not None and len(shown_axes) and axes.turntable:
            values[:, 0] = shown_axes[0, 0]
        ends = np.linalg.inv(axes.base_part(T_base_part, values))[:, :3, 3]
        v, f = capsule_mesh(ends[None], np.array([40.0]))
        traces.append(_solid(v, f, f"track ({k.length_mm:g} mm)", POSITIONER_COLOUR, 0.6))
    return traces


def _solid(v: np.ndarray, f: np.ndarray, name: str, colour: str, opacity: float):
    import plotly.graph_objects as go

    return go.Mesh3d(
        x=v[:, 0], y=v[:, 1], z=v[:, 2], i=f[:, 0], j=f[:, 1], k=f[:, 2], color=colour,
        opacity=opacity, name=name, hoverinfo="name", flatshading=True, showlegend=True,
    )  # fmt: skip
