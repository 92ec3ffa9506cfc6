"""The part's surface as the planners and the metrics see it, in one place: vertical probes of
the CAD, the normals that face out of the part, the directions of the upper hemisphere, area
samples of the surface a top or a hemisphere of views can see, and which of them any beam
within tolerance can reach (the visibility ceiling).
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import trimesh

from scanplan.core.quantities import UP
from scanplan.world.part import Part
from scanplan.world.sample_grid import SampleGrid

# A face steeper than this (from facing the view) returns too little light to count as seen.
COVERAGE_MAX_SLOPE_DEG = 80.0
# The directions that define what the upper hemisphere sees (the surface `--views auto`
# inspects): +Z and rings up to this tilt.
HEMISPHERE_MAX_TILT_DEG = 75.0
# A view's axis at most this far from +Z: a vertical wall is then seen 10° off its normal,
# inside the 15° tolerance with room for tracking, and the sensor stays above it.
VIEW_AXIS_MAX_TILT_DEG = 80.0
# Beam directions tried per sample for the visibility ceiling: the normal, the cone's beam
# nearest +Z, then random ones in the tolerance cone.
CEILING_BEAMS = 24
# The smallest cell of the grid `VisibleSurface.near` looks samples up in: a chunk of a scan
# then occupies a few thousand cells, whatever its points' radius.
GRID_CELL_MM = 8.0


def hemisphere_directions(rings: tuple[tuple[float, int], ...] | None = None) -> np.ndarray:
    """(k, 3) unit directions on the upper hemisphere: +Z and rings (tilt deg, count), each
    ring's azimuths offset by half a step from the previous one. Default 28 directions."""
    rings = rings or ((30.0, 6), (55.0, 9), (HEMISPHERE_MAX_TILT_DEG, 12))
    out = [UP]
    for i, (tilt, count) in enumerate(rings):
        az = (np.arange(count) + 0.5 * (i % 2)) * 2 * math.pi / count
        t = math.radians(tilt)
        out.append(
            np.stack(
                [math.sin(t) * np.cos(az), math.sin(t) * np.sin(az), 0 * az + math.cos(t)], axis=1
            )
        )
    return np.vstack(out)


def oriented_normals(part: Part) -> np.ndarray:
    """(f, 3) face normals pointing out of the part, towards where a sensor could be. A closed,
    consistently wound mesh's own normals; otherwise (real CAD exports) each face's normal
    is turned to the side from which a ray escapes the part (if both, upwards); the part
    alone: what holds it (its fixtures) does not turn its faces."""
    if part.turned_from is not None:  # the original's, turned (a view of the part)
        base, R = part.turned_from
        return oriented_normals(base) @ R[:3, :3].T
    # Once per part while it lives: every evaluation (and every trial) of it asks again.
    if (known := _NORMALS.get(part)) is None:
        known = _NORMALS[part] = _oriented_normals(part)
        known.setflags(write=False)
    return known


_NORMALS: weakref.WeakKeyDictionary[Part, np.ndarray] = weakref.WeakKeyDictionary()


def _oriented_normals(part: Part) -> np.ndarray:
    mesh = part.mesh
    normals = np.asarray(part.ray_engine.face_normals)
    if mesh.is_watertight and mesh.is_winding_consistent:
        # The sign of the enclosed volume: trimesh's `volume` integrates the inertia too
        # (0.3 s on the door's 350k faces).
        tri = np.asarray(mesh.triangles)
        volume6 = np.einsum("ij,ij->", tri[:, 0], np.cross(tri[:, 1], tri[:, 2]))
        return normals * (1.0 if volume6 >= 0 else -1.0)
    centre = np.asarray(mesh.triangles_center)
    far = np.full(len(normals), 1e6)
    eps = 1e-3 * float(np.linalg.norm(part.extents)) + 0.05
    alone = part.ray_engine.alone
    front = ~alone.occluded(centre + eps * normals, normals, far)
    back = ~alone.occluded(centre - eps * normals, -normals, far)
    flip = (back & ~front) | (back & front & (normals[:, 2] < 0))
    return np.where(flip[:, None], -normals, normals)


@dataclass(frozen=True)
class LineProbe:
    """The CAD surface under a pass by vertical rays: k advances x c lateral columns.

    hit: (k, c) bool; z_mm: (k, c) surface height (part frame; meaningless where no hit);
    normals_up: (k, c, 3) face normals turned up (0 where no hit).
    """

    hit: np.ndarray
    z_mm: np.ndarray
    normals_up: np.ndarray


def probe_grid(
    part: Part,
    origin: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    advances_mm: np.ndarray,
    lateral_mm: np.ndarray,
) -> LineProbe:
    """Vertical rays on a horizontal grid, origin + a·u + l·v (a raster's own frame), from
    10 mm above the part (and its fixtures, up to the height of `origin`, the sensor's: what
    they hide is no surface to follow), in one batch; of a part with a region of interest,
    a ray whose first hit is not on it counts as no hit."""
    top = float(part.bounds[1, 2]) + 10.0
    if part.occluders:
        held_down = max(float(m.bounds[1, 2]) for m in part.occluders) + 10.0
        top = max(top, min(held_down, float(origin[2])))
    base = (
        origin
        + np.asarray(advances_mm)[:, None, None] * u
        + np.asarray(lateral_mm)[None, :, None] * v
    )
    origins = base.reshape(-1, 3).copy()
    origins[:, 2] = top
    t, face, normals = part.ray_engine.cast_down(origins)
    shape = (len(advances_mm), len(lateral_mm))
    hit = (face >= 0) & part.inspect_mask[face]
    return LineProbe(hit.reshape(shape), top - t.reshape(shape), normals.reshape(*shape, 3))


def aligning_angles(normals: np.ndarray, u: np.ndarray, v: np.ndarray, roll: bool = True):
    """The pitch θ and roll φ that turn the beam against `normals` (..., 3) in a swath frame
    (u, v, up). With roll, beam = −normal gives sinθ = n_u, cosθ·sinφ = −n_v,
    cosθ·cosφ = n_w (`Swath.poses`); without (the paper's model), the pitch that faces the
    normal's projection on the u-w plane, and φ = 0."""
    n_u, n_v, n_w = normals @ u, normals @ v, normals[..., 2]
    if not roll:
        return np.arctan2(n_u, np.maximum(n_w, 1e-9)), np.zeros_like(n_u)
    return np.arctan2(n_u, np.hypot(n_v, n_w)), np.arctan2(-n_v, np.maximum(n_w, 1e-9))


@dataclass(frozen=True)
class VisibleSurface:
    """Area-uniform samples of the visible surface to inspect. points: (k, 3); area_mm2:
    total; faces: (k,) the face each sample lies on."""

    points: np.ndarray
    area_mm2: float
    faces: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @cached_property
    def _grids(self) -> dict[float, SampleGrid]:
        return {}

    def grid_cell(self, radius_mm: float) -> float:
        """The cell of the grid `near` looks within `radius_mm` on."""
        return max(float(radius_mm), GRID_CELL_MM)

    def near(self, points: np.ndarray, radius_mm: float) -> np.ndarray:
        """Indices of the samples that may lie within `radius_mm` of `points` (n, 3), in
        their grid cells' order: every one that does, and some farther (those in the same
        cells of a grid at least `GRID_CELL_MM` wide, built once per cell size: choosing
        views and every trial judge on the same samples)."""
        cell = self.grid_cell(radius_mm)
        grid = self._grids.get(cell)
        if grid is None:
            grid = self._grids[cell] = SampleGrid(self.points, cell)
        return grid.near(points)


def area_samples(
    part: Part, candidate: np.ndarray, spacing_mm: float, seed: int
) -> tuple[np.ndarray, np.ndarray, float]:
    """About one point per spacing² of the `candidate` faces' area (20 000..400 000),
    uniform by area, seeded (`trimesh.sample.sample_surface`): (points (k, 3), faces (k,),
    candidate area)."""
    area = np.asarray(part.mesh.area_faces)
    cand_area = float(area[candidate].sum())
    if cand_area <= 0:
        return np.zeros((0, 3)), np.zeros(0, np.int64), 0.0
    count = int(np.clip(cand_area / spacing_mm**2, 20_000, 400_000))
    weight = np.where(candidate, area, 0.0)
    points, faces = trimesh.sample.sample_surface(part.mesh, count, face_weight=weight, seed=seed)
    return np.asarray(points, np.float64), np.asarray(faces, np.int64), cand_area


# Samples drawn once per part while it lives: choosing views evaluates every candidate on
# the same samples (on the NIST sheet metal part, 15 draws were 13 % of its planning time).
_SAMPLES: weakref.WeakKeyDictionary[Part, dict[tuple[str, float, int], VisibleSurface]] = (
    weakref.WeakKeyDictionary()
)


def _once(
    kind: str, part: Part, spacing_mm: float, seed: int, draw: Callable[[], VisibleSurface]
) -> VisibleSurface:
    """The samples `draw` gives, drawn once per (part, kind, spacing, seed), read-only."""
    by_key = _SAMPLES.setdefault(part, {})
    key = (kind, float(spacing_mm), int(seed))
    if key not in by_key:
        surface = draw()
        surface.points.setflags(write=False)
        surface.faces.setflags(write=False)
        by_key[key] = surface
    return by_key[key]


def hemisphere_visible_samples(
    part: Part, spacing_mm: float, seed: int = 0, directions: np.ndarray | None = None
) -> VisibleSurface:
    """The surface a sensor can see from the upper hemisphere (`--views auto`): samples of
    the faces to inspect (any slope) kept if, along at least one of `directions` (default
    `hemisphere_directions`, 28 directions up to 75° from +Z), the face is within
    COVERAGE_MAX_SLOPE_DEG of facing it (either winding) and a ray from it escapes the part
    (the part alone: a surface its fixtures hide is still to inspect, and out of reach).
    With the default directions, drawn once per part (read-only arrays)."""
    if directions is None:
        return _once(
            "hemisphere",
            part,
            spacing_mm,
            seed,
            lambda: _hemisphere_visible(part, spacing_mm, seed, hemisphere_directions()),
        )
    return _hemisphere_visible(part, spacing_mm, seed, np.asarray(directions, float))


def _hemisphere_visible(
    part: Part, spacing_mm: float, seed: int, dirs: np.ndarray
) -> VisibleSurface:
    points, faces, cand_area = area_samples(part, part.inspect_mask, spacing_mm, seed)
    n = part.ray_engine.face_normals[faces]
    facing_cos = math.cos(math.radians(COVERAGE_MAX_SLOPE_DEG))
    visible = np.zeros(len(points), bool)
    for d in dirs:
        cos = n @ d
        todo = np.flatnonzero(~visible & (np.abs(cos) > facing_cos))
        if len(todo) == 0:
            continue
        start = points[todo] + np.sign(cos[todo])[:, None] * n[todo] * 0.05
        ray = np.broadcast_to(d, start.shape)
        visible[todo] = ~part.ray_engine.alone.occluded(start, ray, np.full(len(todo), 1e6))
    frac = float(visible.mean()) if len(visible) else 0.0
    return VisibleSurface(points[visible], cand_area * frac, faces[visible])


def upward_visible_samples(part: Part, spacing_mm: float, seed: int = 0) -> VisibleSurface:
    """Sample faces within COVERAGE_MAX_SLOPE_DEG of horizontal (either winding) at about one
    point per spacing² of area; keep the samples from which a vertical ray escapes. Only the
    part's faces to inspect (its region of interest) are sampled; the whole part occludes,
    its fixtures do not (what they hide is to inspect, and out of reach). Drawn once per
    part (read-only arrays)."""
    return _once("top", part, spacing_mm, seed, lambda: _upward_visible(part, spacing_mm, seed))


def _upward_visible(part: Part, spacing_mm: float, seed: int) -> VisibleSurface:
    normals = part.ray_engine.face_normals
    steep_cos = math.cos(math.radians(COVERAGE_MAX_SLOPE_DEG))
    candidate = (np.abs(normals[:, 2]) > steep_cos) & part.inspect_mask
    points, faces, cand_area = area_samples(part, candidate, spacing_mm, seed)
    if cand_area <= 0:
        return VisibleSurface(np.zeros((0, 3)), 0.0)
    count = len(points)
    up_normal = normals[faces] * np.sign(normals[faces, 2:3])
    start = points + up_normal * 0.05  # off the face, above float32 error at part scale
    up = np.tile([0.0, 0.0, 1.0], (count, 1))
    blocked = part.ray_engine.alone.occluded(start, up, np.full(count, 1e6))
    visible = ~blocked
    return VisibleSurface(points[visible], cand_area * float(visible.mean()), faces[visible])


def unit_perpendicular(v: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(k, 3) random unit vectors perpendicular to the rows of v."""
    side = rng.normal(size=v.shape)
    side -= np.sum(side * v, axis=1, keepdims=True) * v
    return side / np.maximum(np.linalg.norm(side, axis=1, keepdims=True), 1e-12)


def towards_up(n: np.ndarray, angle_rad: float) -> np.ndarray:
    """(k, 3): the unit vectors `n` turned towards +Z by up to `angle_rad` (+Z itself where it
    is nearer than that)."""
    return turned_towards(n, UP, angle_rad)


def turned_towards(n: np.ndarray, to: np.ndarray, angle_rad: float) -> np.ndarray:
    """(k, 3): the unit vectors `n` turned towards the unit vector `to` by up to `angle_rad`
    (`to` itself where it is nearer than that)."""
    cos_to = np.clip(n @ to, -1.0, 1.0)
    side = to - cos_to[:, None] * n
    norm = np.linalg.norm(side, axis=1, keepdims=True)
    side = np.where(norm > 1e-9, side / np.maximum(norm, 1e-12), 0.0)
    turn = np.minimum(np.arccos(cos_to), angle_rad)[:, None]
    return np.cos(turn) * n + np.sin(turn) * side


def reachable_samples(
    part: Part,
    surface: VisibleSurface,
    tol_rad: float,
    max_tilt_deg: float = VIEW_AXIS_MAX_TILT_DEG,
    beams: int = CEILING_BEAMS,
    seed: int = 0,
    also: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> np.ndarray:
    """(k,) bool: the samples of `surface` some beam reaches unobstructed from within `tol_rad`
    of the face's outward normal and at most `max_tilt_deg` from +Z (`beams` directions per
    sample: the normal, the cone's beam nearest +Z, then uniform in the cone, seeded). Their
    share is the visibility ceiling: no plan holds more of the surface in spec, since a point
    in spec was measured by such a beam. The part's fixtures (`Part.among`) block beams too.
    It ignores the depth window, the sensor body and the camera's line of sight;
    `also(samples, ray starts, beams) -> (k,) bool` adds a test a beam must pass too (a
    benchmark's camera). Without `also`, found once per (part, samples, tolerance, tilt,
    beams, seed) while the part lives (read-only): it does not depend on the plan, and
    choosing views, `evaluate`, the demo and `compare` ask it of the same part again."""
    if also is not None:
        return _reachable(part, surface, tol_rad, max_tilt_deg, beams, seed, also)
    by_key = _REACHABLE.setdefault(part, {})
    key = (id(surface), float(tol_rad), float(max_tilt_deg), int(beams), int(seed))
    if key not in by_key or by_key[key][0] is not surface:
        seen = _reachable(part, surface, tol_rad, max_tilt_deg, beams, seed, None)
        seen.setflags(write=False)
        by_key[key] = (surface, seen)  # the samples kept too: their id stays theirs
    return by_key[key][1]


# The reachable samples found per part while it lives (`reachable_samples`).
_REACHABLE: weakref.WeakKeyDictionary[
    Part, dict[tuple[int, float, float, int, int], tuple[VisibleSurface, np.ndarray]]
] = weakref.WeakKeyDictionary()


def _reachable(
    part: Part,
    surface: VisibleSurface,
    tol_rad: float,
    max_tilt_deg: float,
    beams: int,
    seed: int,
    also: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None,
) -> np.ndarray:
    """`reachable_samples`, found here."""
    seen = np.zeros(len(surface.points), bool)
    if len(seen) == 0:
        return seen
    rng = np.random.default_rng(seed)
    n = oriented_normals(part)[surface.faces]
    lowest = math.cos(math.radians(max_tilt_deg)) - 1e-9
    for b in range(beams):
        todo = np.flatnonzero(~seen)
        if len(todo) == 0:
            break
        if b == 0:
            beam = n[todo]
        elif b == 1:
            # A wall is reached only by the cone's top edge, which random beams often miss.
            beam = towards_up(n[todo], tol_rad)
        else:
            # Uniform by solid angle in the cone (near enough for a 15° cone), seeded.
            angle = tol_rad * np.sqrt(rng.random(len(todo)))[:, None]
            beam = np.cos(angle) * n[todo] + np.sin(angle) * unit_perpendicular(n[todo], rng)
        steep = beam[:, 2] < lowest
        todo, beam = todo[~steep], beam[~steep]
        if len(todo):
            start = surface.points[todo] + 0.05 * n[todo]  # off the face, as the samplers do
            far = np.full(len(todo), 1e6)
            escapes = ~part.ray_engine.occluded(start, beam, far)
            if also is not None:
                escapes &= also(todo, start, beam)
            seen[todo] = escapes
    return seen
