"""The Boustrophedon base path (SPEC §3): parallel passes over the part's footprint.

A `Swath` is one pass, with its own frame: u = scan direction (horizontal), v = lateral,
w = up. During a pass only the position in the u-w plane and the pitch theta (about x_s = v)
change; `Swath.pose` turns those three numbers into a sensor pose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import trimesh
from scipy.spatial import ConvexHull, QhullError

from scanplan.core.limits import MAX_PASSES, check_count
from scanplan.core.plan_records import checked_swath_record
from scanplan.core.quantities import OVERLAP, UP
from scanplan.core.sensor_spec import SensorSpec
from scanplan.world.part import Part
from scanplan.world.surface import LineProbe, probe_grid


@dataclass(frozen=True)
class Swath:
    """One pass from `start_mm` to `end_mm` (sensor positions, part frame, at the pass's
    nominal height: the top of the part under the pass + W_d).

    index: order in the snake; u, v: (3,) unit scan and lateral directions (u x v = up).
    band_mm: the lateral band (along v, from the centre line) of the line expected in spec
    on this pass (adaptive passes), None = the whole line.
    """

    index: int
    start_mm: np.ndarray
    end_mm: np.ndarray
    u: np.ndarray
    v: np.ndarray
    band_mm: tuple[float, float] | None = None

    @property
    def length_mm(self) -> float:
        return float(np.dot(self.end_mm - self.start_mm, self.u))

    def pose(
        self,
        s_mm: float,
        h_mm: float,
        pitch_rad: float,
        roll_rad: float = 0.0,
        lateral_mm: float = 0.0,
    ) -> np.ndarray:
        """T_part_sensor at advance s along u, lateral offset l along v and height h above
        `start_mm`: rolled by φ about u (φ > 0 tilts the beam towards +v), then pitched by θ
        about the sensor's x_s (θ > 0 tilts the beam backwards, towards −u). The beam is
        z_s = −sinθ·u + cosθ·(sinφ·v − cosφ·w)."""
        return self.poses(
            np.array([s_mm]),
            np.array([h_mm]),
            np.array([pitch_rad]),
            np.array([roll_rad]),
            np.array([lateral_mm]),
        )[0]

    def poses(
        self,
        s_mm: np.ndarray,
        h_mm: np.ndarray,
        pitch_rad: np.ndarray,
        roll_rad: np.ndarray | None = None,
        lateral_mm: np.ndarray | None = None,
    ) -> np.ndarray:
        """Vectorized `pose`: (k,) x3 (+ roll, lateral) -> (k, 4, 4)."""
        return frame_poses(
            self.start_mm, self.u, self.v, s_mm, h_mm, pitch_rad, roll_rad, lateral_mm
        )

    def probe(self, part: Part, advances_mm: np.ndarray, lateral_mm: np.ndarray) -> LineProbe:
        """The CAD under this pass: vertical rays at the given advances along u (from
        `start_mm`) and lateral offsets along v, from 10 mm above the part, in one batch. Of a
        part with a region of interest, a ray whose first hit is not on it counts as no hit:
        the pass follows the ROI."""
        return probe_grid(part, self.start_mm, self.u, self.v, advances_mm, lateral_mm)

    def sees_nothing(self, part: Part) -> ValueError:
        """The error of this pass meeting no surface of `part`, saying why it may be."""
        why = "the part is outside the sensor's reach"
        if part.occluders:
            why += " or its fixtures (--fixture) hide it"
        return ValueError(f"pass {self.index} sees no surface of part {part.name}: {why}")

    def to_swath_frame(self, T_part_sensor: np.ndarray) -> tuple[float, float, float]:
        """(s, h, theta) of a pose of this pass; inverse of `pose`."""
        d = T_part_sensor[:3, 3] - self.start_mm
        z_s = T_part_sensor[:3, 2]
        theta = math.atan2(-float(np.dot(z_s, self.u)), -float(np.dot(z_s, UP)))
        return float(np.dot(d, self.u)), float(np.dot(d, UP)), theta


def swath_record(swath: Swath, index: int | None = None) -> dict:
    """A pass line as a plan file records it (JSON-able, exact floats), read back by
    `swath_from_record`; index: its number in the file (default: the swath's own)."""
    return {
        "index": int(swath.index if index is None else index),
        "start_mm": [float(c) for c in swath.start_mm],
        "end_mm": [float(c) for c in swath.end_mm],
        "u": [float(c) for c in swath.u],
        "v": [float(c) for c in swath.v],
        "band_mm": None if swath.band_mm is None else [float(c) for c in swath.band_mm],
    }


def swath_from_record(record: object, where: str) -> Swath:
    """The Swath a plan file records (`swath_record`); ValueError naming `where` and the
    field (a point or a length out of range, a direction not unit) before any work."""
    data = checked_swath_record(record, where)
    start, end, u, v = (
        np.array(data[key], dtype=np.float64) for key in ("start_mm", "end_mm", "u", "v")
    )
    band = data.get("band_mm")
    return Swath(data["index"], start, end, u, v, None if band is None else (band[0], band[1]))


def frame_poses(
    start_mm: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    s_mm: np.ndarray,
    h_mm: np.ndarray,
    pitch_rad: np.ndarray,
    roll_rad: np.ndarray | None = None,
    lateral_mm: np.ndarray | None = None,
) -> np.ndarray:
    """`Swath.poses` of a pass from `start_mm` along `u`, `v` ((3,) each, or (k, 3): one
    pass per pose, so that poses of several passes are made in one call) -> (k, 4, 4)."""
    s, h, th = (np.asarray(a, dtype=np.float64).reshape(-1) for a in (s_mm, h_mm, pitch_rad))
    c, sn = np.cos(th), np.sin(th)
    poses = np.zeros((len(s), 4, 4))
    poses[:, 3, 3] = 1.0
    poses[:, :3, 0] = v  # x_s: along the laser line
    poses[:, :3, 1] = c[:, None] * u - sn[:, None] * UP  # y_s: forward
    poses[:, :3, 2] = -sn[:, None] * u - c[:, None] * UP  # z_s: the beam
    poses[:, :3, 3] = start_mm + s[:, None] * u + h[:, None] * UP
    if roll_rad is not None and np.any(np.asarray(roll_rad) != 0):
        # Roll about u first, then pitch about the rolled x_s: on a steep flank the big
        # rotation is the roll and the pitch stays small (pitch-then-roll would need a
        # pitch that swings with every small change of the normal along the pass).
        phi = np.broadcast_to(np.asarray(roll_rad, dtype=np.float64).reshape(-1), s.shape)
        cp, sp = np.cos(phi)[:, None], np.sin(phi)[:, None]
        z1 = sp * v - cp * UP
        poses[:, :3, 0] = cp * v + sp * UP
        poses[:, :3, 1] = c[:, None] * u + sn[:, None] * z1
        poses[:, :3, 2] = -sn[:, None] * u + c[:, None] * z1
    if lateral_mm is not None and np.any(np.asarray(lateral_mm) != 0):
        lat = np.broadcast_to(np.asarray(lateral_mm, dtype=np.float64).reshape(-1), s.shape)
        poses[:, :3, 3] += lat[:, None] * v
    return poses


def rectangle_axes(part: Part) -> tuple[np.ndarray, np.ndarray]:
    """The long and the short axis (unit, horizontal) of the minimum-area rectangle around the
    part seen from above."""
    xy = np.asarray(
        part.inspect_vertices if part.inspect_faces is not None else part.mesh.vertices
    )[:, :2]  # the region of interest's footprint, if any
    try:
        # The footprint's 2-D hull: what the rectangle depends on, and much cheaper than the
        # mesh's 3-D hull on a part of 10^5 vertices.
        points = xy[ConvexHull(xy).vertices]
        transform, extents = trimesh.bounds.oriented_bounds_2D(points)
    except QhullError:  # a footprint that is a line (a vertical plate): its bounding box
        transform, extents = np.eye(3), np.ptp(xy, axis=0)
    # transform maps the points into the rectangle's frame; its rows are the axes.
    long_i = 0 if extents[0] >= extents[1] else 1
    axes = [np.array([transform[i, 0], transform[i, 1], 0.0]) for i in (long_i, 1 - long_i)]
    return axes[0], axes[1]


def cross_line_residual_mm(
    part: Part, u: np.ndarray, line_width_mm: float, overlap: float = OVERLAP, grid_mm: float = 10.0
) -> float:
    """Mean |height - mean height| across the laser line, over passes along u.

    During a pass only height and pitch follow the surface (roll is fixed), so what varies
    across the line (along v) within one station is error no planner can remove. Heights come
    from vertical rays on a grid over the footprint (of the region of interest, if any: rays
    that meet another face of the part first are left out).
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.cross(UP, u)
    roi = part.inspect_vertices
    lo, hi = roi.min(axis=0), part.bounds[1]
    top = roi.max(axis=0)
    xs = np.arange(lo[0], top[0] + grid_mm, grid_mm)
    ys = np.arange(lo[1], top[1] + grid_mm, grid_mm)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    origins = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, hi[2] + 10.0)], axis=1)
    t, face, _ = part.ray_engine.cast_down(origins)
    hit = (face >= 0) & part.inspect_mask[face]
    if hit.sum() < 2:
        return 0.0
    points = origins[hit] - t[hit, None] * UP
    along, across = points @ u, points @ v
    step = line_width_mm * (1.0 - overlap)
    lane = np.floor((across - across.min()) / step).astype(np.int64)
    station = np.floor((along - along.min()) / grid_mm).astype(np.int64)
    group = lane * (station.max() + 1) + station
    _, group = np.unique(group, return_inverse=True)
    count = np.bincount(group)
    mean = np.bincount(group, points[:, 2]) / count
    return float(np.mean(np.abs(points[:, 2] - mean[group])))


class DirectionRule(Protocol):
    """How a raster picks its scan direction u (unit, horizontal) for a part."""

    def direction(self, part: Part, sensor: SensorSpec) -> np.ndarray: ...


@dataclass(frozen=True)
class GivenDirection:
    """A direction given by the user ('x', 'y' or a vector); its vertical part is dropped."""

    vector: tuple[float, float, float]

    def direction(self, part: Part, sensor: SensorSpec) -> np.ndarray:
        return np.array(self.vector, dtype=np.float64)


@dataclass(frozen=True)
class LongSide:
    """The long side of the minimum-area rectangle around the part seen from above (SPEC §3)."""

    def direction(self, part: Part, sensor: SensorSpec) -> np.ndarray:
        return rectangle_axes(part)[0]


@dataclass(frozen=True)
class LeastCrossResidual:
    """Of the rectangle's two sides, the one whose passes leave less surface variation across
    the laser line (what height and pitch cannot follow); the long side unless the short one
    is clearly (`margin`, 25 %) better — so a plate or a training piece scans along its
    length, a car door across the tumblehome."""

    overlap: float = OVERLAP
    margin: float = 0.25

    def direction(self, part: Part, sensor: SensorSpec) -> np.ndarray:
        long_axis, short_axis = rectangle_axes(part)
        width = sensor.line_width_mm
        along_long = cross_line_residual_mm(part, long_axis, width, self.overlap)
        along_short = cross_line_residual_mm(part, short_axis, width, self.overlap)
        return short_axis if along_short < (1 - self.margin) * along_long else long_axis


def direction_rule(direction: str | np.ndarray | DirectionRule, overlap: float = OVERLAP):
    """The rule for a CLI-style direction: 'x', 'y', 'long', 'auto', a vector, or a rule."""
    if isinstance(direction, str):
        rules: dict[str, DirectionRule] = {
            "x": GivenDirection((1.0, 0.0, 0.0)),
            "y": GivenDirection((0.0, 1.0, 0.0)),
            "long": LongSide(),
            "auto": LeastCrossResidual(overlap),
        }
        try:
            return rules[direction.lower()]
        except KeyError:
            raise ValueError(
                f"unknown scan direction {direction!r}: use x, y, long or auto"
            ) from None
    if isinstance(direction, np.ndarray | list | tuple):
        x, y, z = (float(c) for c in np.asarray(direction, dtype=np.float64).reshape(3))
        return GivenDirection((x, y, z))
    return direction


def scan_direction(
    part: Part,
    sensor: SensorSpec,
    direction: str | np.ndarray | DirectionRule = "auto",
    overlap: float = OVERLAP,
) -> np.ndarray:
    """Unit horizontal scan direction from a direction rule (see `direction_rule`), with a
    canonical sign (first non-zero component positive) so plans are reproducible."""
    u = np.asarray(direction_rule(direction, overlap).direction(part, sensor), dtype=np.float64)
    u = u.copy()
    u[2] = 0.0
    norm = np.linalg.norm(u)
    if norm < 1e-9:
        raise ValueError("scan direction must have a horizontal component")
    u = u / norm
    if u[0] < -1e-9 or (abs(u[0]) <= 1e-9 and u[1] < 0):
        u = -u
    return u


def plan_swaths(
    part: Part,
    sensor: SensorSpec,
    direction: str | np.ndarray | DirectionRule = "auto",
    overlap: float = OVERLAP,
    run_in_mm: float = 20.0,
    uphill: np.ndarray | None = None,
) -> list[Swath]:
    """Passes covering the part's footprint (its region of interest's, if it has one),
    centred on it, in snake order (none downhill toward a table: `swaths_at`).

    Lateral step d = w * (1 - overlap), w the line width at W_d; a part narrower than w gets
    one pass along its centre line. Each pass spans the part's extent along u plus `run_in_mm`
    at each end, at height (highest point of the part under the line) + W_d.
    """
    if not 0.0 <= overlap < 1.0:
        raise ValueError(f"overlap must be in [0, 1), got {overlap}")
    u = scan_direction(part, sensor, direction, overlap)
    v = np.cross(UP, u)
    across = part.inspect_vertices @ v  # the region of interest's footprint, if any
    width = sensor.line_width_mm
    step = width * (1.0 - overlap)
    span = float(across.max() - across.min())
    n_pass = 1 if span <= width else 1 + math.ceil((span - width) / step - 1e-9)
    check_count(
        n_pass, MAX_PASSES, f"passes of one view (overlap {overlap!r})", "a smaller overlap"
    )
    centre = 0.5 * (across.max() + across.min())
    offsets = centre + (np.arange(n_pass) - (n_pass - 1) / 2) * step
    return swaths_at(
        part, sensor, u, offsets, [(-width / 2, width / 2)] * n_pass, run_in_mm, uphill=uphill
    )


# A pass whose direction descends toward the table by more than this (sin 10°) is flown the
# other way (`swaths_at`).
DOWNHILL_SIN = 0.17


def swaths_at(
    part: Part,
    sensor: SensorSpec,
    u: np.ndarray,
    offsets: np.ndarray | list[float],
    bands: list[tuple[float, float]],
    run_in_mm: float,
    adaptive: bool = False,
    uphill: np.ndarray | None = None,
) -> list[Swath]:
    """Passes along u at the lateral `offsets`, each at (highest point under its band) + W_d,
    spanning the part's extent along u plus `run_in_mm` at each end, in snake order. With
    `uphill` (away from the table, in this frame), a pass that would run downhill by more
    than `DOWNHILL_SIN` runs the other way: the sensor body reaches far ahead on its camera
    side, which must not lead it into the table (a side view of a wall)."""
    v = np.cross(UP, u)
    vertices = part.inspect_vertices
    along, across = vertices @ u, vertices @ v
    s0, s1 = float(along.min()) - run_in_mm, float(along.max()) + run_in_mm
    swaths = []
    for i, (offset, (lo, hi)) in enumerate(zip(offsets, bands, strict=True)):
        under = (across >= offset + lo) & (across <= offset + hi)
        top = float(vertices[under, 2].max()) if under.any() else float(vertices[:, 2].max())
        a = s0 * u + offset * v + (top + sensor.working_distance_mm) * UP
        b = s1 * u + offset * v + (top + sensor.working_distance_mm) * UP
        band = (lo, hi) if adaptive else None
        backwards = i % 2 == 1  # snake order: every other pass runs backwards
        if uphill is not None and abs(float(u @ uphill)) > DOWNHILL_SIN:
            backwards = float(u @ uphill) < 0  # every pass uphill
        if backwards:  # v flips with u
            flipped = (-hi, -lo) if band is not None else None
            swaths.append(Swath(i, b, a, -u, -v, flipped))
        else:
            swaths.append(Swath(i, a, b, u, v, band))
    return swaths
