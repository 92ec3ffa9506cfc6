"""The Boustrophedon base path (SPEC §3): parallel passes over the part's footprint.

A `Swath` is one pass, with its own frame: u = scan direction (horizontal), v = lateral,
w = up. During a pass only the position in the u-w plane and the pitch theta (about x_s = v)
change; `Swath.pose` turns those three numbers into a sensor pose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import trimesh

from scanplan.part import Part
from scanplan.sensor import SensorSpec

UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Swath:
    """One pass from `start_mm` to `end_mm` (sensor positions, part frame, at the pass's
    nominal height: the top of the part under the pass + W_d).

    index: order in the snake; u, v: (3,) unit scan and lateral directions (u x v = up).
    """

    index: int
    start_mm: np.ndarray
    end_mm: np.ndarray
    u: np.ndarray
    v: np.ndarray

    @property
    def length_mm(self) -> float:
        return float(np.dot(self.end_mm - self.start_mm, self.u))

    def pose(self, s_mm: float, h_mm: float, pitch_rad: float) -> np.ndarray:
        """T_part_sensor at advance s along u and height h above `start_mm`, pitched by theta
        about x_s (theta > 0 tilts the beam backwards, towards -u)."""
        return self.poses(np.array([s_mm]), np.array([h_mm]), np.array([pitch_rad]))[0]

    def poses(self, s_mm: np.ndarray, h_mm: np.ndarray, pitch_rad: np.ndarray) -> np.ndarray:
        """Vectorized `pose`: (k,) x3 -> (k, 4, 4)."""
        s, h, th = (np.asarray(a, dtype=np.float64).reshape(-1) for a in (s_mm, h_mm, pitch_rad))
        c, sn = np.cos(th), np.sin(th)
        poses = np.zeros((len(s), 4, 4))
        poses[:, 3, 3] = 1.0
        poses[:, :3, 0] = self.v  # x_s: along the laser line
        poses[:, :3, 1] = c[:, None] * self.u - sn[:, None] * UP  # y_s: forward
        poses[:, :3, 2] = -sn[:, None] * self.u - c[:, None] * UP  # z_s: the beam
        poses[:, :3, 3] = self.start_mm + s[:, None] * self.u + h[:, None] * UP
        return poses

    def to_swath_frame(self, T_part_sensor: np.ndarray) -> tuple[float, float, float]:
        """(s, h, theta) of a pose of this pass; inverse of `pose`."""
        d = T_part_sensor[:3, 3] - self.start_mm
        z_s = T_part_sensor[:3, 2]
        theta = math.atan2(-float(np.dot(z_s, self.u)), -float(np.dot(z_s, UP)))
        return float(np.dot(d, self.u)), float(np.dot(d, UP)), theta


def scan_direction(part: Part, direction: str | np.ndarray = "auto") -> np.ndarray:
    """Unit horizontal scan direction: 'x', 'y', a vector, or 'auto' = the long side of the
    minimum-area rectangle around the part seen from above."""
    if isinstance(direction, str):
        key = direction.lower()
        if key == "x":
            return np.array([1.0, 0.0, 0.0])
        if key == "y":
            return np.array([0.0, 1.0, 0.0])
        if key != "auto":
            raise ValueError(f"unknown scan direction {direction!r}: use x, y or auto")
        hull = part.mesh.convex_hull.vertices[:, :2]
        transform, extents = trimesh.bounds.oriented_bounds_2D(hull)
        # transform maps the points into the rectangle's frame; its rows are the axes.
        axis = transform[0, :2] if extents[0] >= extents[1] else transform[1, :2]
        u = np.array([axis[0], axis[1], 0.0])
    else:
        u = np.asarray(direction, dtype=np.float64).copy()
        u[2] = 0.0
    norm = np.linalg.norm(u)
    if norm < 1e-9:
        raise ValueError("scan direction must have a horizontal component")
    u /= norm
    # A canonical sign (first non-zero component positive) keeps plans reproducible.
    if u[0] < -1e-9 or (abs(u[0]) <= 1e-9 and u[1] < 0):
        u = -u
    return u


def plan_swaths(
    part: Part,
    sensor: SensorSpec,
    direction: str | np.ndarray = "auto",
    overlap: float = 0.2,
    run_in_mm: float = 20.0,
) -> list[Swath]:
    """Passes covering the part's footprint, centred on it, in snake order.

    Lateral step d = w * (1 - overlap), w the line width at W_d; a part narrower than w gets
    one pass along its centre line. Each pass spans the part's extent along u plus `run_in_mm`
    at each end, at height (highest point of the part under the line) + W_d.
    """
    if not 0.0 <= overlap < 1.0:
        raise ValueError(f"overlap must be in [0, 1), got {overlap}")
    u = scan_direction(part, direction)
    v = np.cross(UP, u)
    vertices = np.asarray(part.mesh.vertices)
    along, across = vertices @ u, vertices @ v
    width = sensor.line_width_mm
    step = width * (1.0 - overlap)
    span = float(across.max() - across.min())
    n_pass = 1 if span <= width else 1 + math.ceil((span - width) / step - 1e-9)
    centre = 0.5 * (across.max() + across.min())
    offsets = centre + (np.arange(n_pass) - (n_pass - 1) / 2) * step
    s0, s1 = float(along.min()) - run_in_mm, float(along.max()) + run_in_mm

    swaths = []
    for i, offset in enumerate(offsets):
        under = np.abs(across - offset) <= width / 2
        top = float(vertices[under, 2].max()) if under.any() else float(vertices[:, 2].max())
        a = s0 * u + offset * v + (top + sensor.working_distance_mm) * UP
        b = s1 * u + offset * v + (top + sensor.working_distance_mm) * UP
        if i % 2 == 1:  # snake order: every other pass runs backwards
            swaths.append(Swath(i, b, a, -u, -v))
        else:
            swaths.append(Swath(i, a, b, u, v))
    return swaths


def transition_poses(prev: Swath, nxt: Swath, clearance_mm: float = 50.0) -> np.ndarray:
    """Non-scanning moves from the end of one pass to the start of the next: lift clear of the
    part, cross over, descend. (3, 4, 4)."""
    lift = max(prev.end_mm[2], nxt.start_mm[2]) + clearance_mm
    a = prev.pose(prev.length_mm, lift - prev.start_mm[2], 0.0)
    b = nxt.pose(0.0, lift - nxt.start_mm[2], 0.0)
    c = nxt.pose(0.0, 0.0, 0.0)
    return np.stack([a, b, c])
