"""Passes that adapt to the surface (SPEC §3b): the band of the laser line that stays in spec.

A 495 mm line on a curved part is in spec (|z_s − W_d| ≤ tol_d, α_i ≤ tol_α) only on a band
around where the beam is aligned with the surface. `in_spec_bands` predicts that band for a
pass centred at a lateral offset, from the CAD's top surface (vertical rays on a grid), with
the beam aligned — by pitch and roll — to the surface normal at the band's centre.
`adaptive_offsets` chooses pass centres greedily until their bands cover the surface (set
cover): curved parts get closer passes, flat ones fewer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scanplan.core.quantities import UP, ScanSpec, StepLimits
from scanplan.planning.shaping import PITCH_LEVER, ROLL_RATE, CentredLookahead, RobustLookahead
from scanplan.planning.swaths import DirectionRule, Swath, frame_poses, scan_direction, swaths_at
from scanplan.world.part import Part
from scanplan.world.surface import COVERAGE_MAX_SLOPE_DEG, aligning_angles, probe_grid


@dataclass(frozen=True)
class TopSurface:
    """The part's top surface seen from above on a grid in the raster's (u, v) frame.

    along_mm: (k,) and across_mm: (c,) grid coordinates; hit: (k, c); points: (k, c, 3) part
    frame; normals: (k, c, 3) unit, facing up (0 where no hit); u, v: (3,) the raster's axes.
    """

    u: np.ndarray
    v: np.ndarray
    along_mm: np.ndarray
    across_mm: np.ndarray
    hit: np.ndarray
    points: np.ndarray
    normals: np.ndarray


def top_surface(
    part: Part,
    u: np.ndarray,
    v: np.ndarray,
    along_step_mm: float = 20.0,
    across_step_mm: float = 4.0,
    sensor_above_mm: float = math.inf,
) -> TopSurface:
    """Vertical rays on a grid over the part's footprint along u and v (one batch). With a
    region of interest, the grid spans its footprint and a ray whose first hit (on the whole
    part: occlusion stays real) is not one of its faces counts as no surface. Fixtures up
    to `sensor_above_mm` above the part's top (the sensor's height) hide what they cover."""
    vertices = part.inspect_vertices
    a, c = vertices @ u, vertices @ v
    along = np.arange(a.min() + along_step_mm / 2, a.max(), along_step_mm)
    if len(along) == 0:
        along = np.array([0.5 * (a.min() + a.max())])
    across = np.arange(c.min(), c.max() + across_step_mm, across_step_mm)
    sensor = np.array([0.0, 0.0, float(part.bounds[1, 2]) + sensor_above_mm])
    probe = probe_grid(part, sensor, u, v, along, across)
    points = along[:, None, None] * u + across[None, :, None] * v
    points[..., 2] = np.where(probe.hit, probe.z_mm, 0.0)
    return TopSurface(u, v, along, across, probe.hit, points, probe.normals_up)


@dataclass(frozen=True)
class Band:
    """The predicted in-spec band of a pass centred at `centre_mm` (along v): [lo, hi] along v
    (part frame), and per grid row the edges (NaN for rows without surface at the centre)."""

    centre_mm: float
    lo_mm: float
    hi_mm: float
    row_lo_mm: np.ndarray
    row_hi_mm: np.ndarray


# Pass centres whose bands `in_spec_bands` predicts in one batch: its (centres, rows,
# columns, 3) temporaries stay near 8 MB each.
BAND_BATCH_CELLS = 350_000


def in_spec_bands(
    surface: TopSurface,
    centres_mm: np.ndarray,
    spec: ScanSpec,
    margin: float = 0.7,
    centre_halfwidth_mm: float = 5.0,
    row_quantile: float = 0.15,
    limits: StepLimits | None = None,
) -> list[Band]:
    """For each of `centres_mm`, the band around it where the surface would be in spec, per
    grid row, with the beam W_d from the centre point and aligned to the mean normal near it
    as far as the step limits allow, as the geometric planner shapes them: the pitch follows
    that normal along the pass only at `shaping.PITCH_LEVER`/W_d rad per mm (its
    `RobustLookahead`), the roll at `shaping.ROLL_RATE` Δφ_max per Δs_opt.
    A pass's band is a robust envelope over the rows (`row_quantile` of the rows may be
    narrower: a local feature must not shrink a whole pass). `margin` scales both
    tolerances: tracking and noise leave less than the full tolerance. Columns without
    surface count as in spec (nothing there to measure). The centres are predicted together
    (a call for each was 15 % of a machined part's view choice), `BAND_BATCH_CELLS` grid
    cells at a time."""
    centres = np.asarray(centres_mm, dtype=np.float64).reshape(-1)
    per_batch = max(1, BAND_BATCH_CELLS // max(surface.hit.size, 1))
    args = (margin, centre_halfwidth_mm, row_quantile, limits or StepLimits())
    return [
        band
        for lo in range(0, len(centres), per_batch)
        for band in _bands(surface, centres[lo : lo + per_batch], spec, *args)
    ]


def _bands(
    surface: TopSurface,
    centres: np.ndarray,
    spec: ScanSpec,
    margin: float,
    centre_halfwidth_mm: float,
    row_quantile: float,
    lim: StepLimits,
) -> list[Band]:
    """`in_spec_bands` of one batch of (b,) centres: arrays (b, rows, columns)."""
    tol_d = margin * spec.tolerance_mm
    cos_tol = math.cos(margin * spec.tol_angle_rad)
    half_line = spec.sensor.line_width_mm / 2
    wd = spec.working_distance_mm
    across = surface.across_mm
    b, cols = len(centres), len(across)
    # The columns near each centre, padded to the most any centre has (padding: no hit).
    near = np.abs(across[None, :] - centres[:, None]) <= centre_halfwidth_mm
    width = max(int(near.sum(axis=1).max()), 1)
    order = np.argsort(~near, axis=1, kind="stable")[:, :width]  # near columns first, in order
    real = np.take_along_axis(near, order, axis=1)
    hit_c = np.moveaxis(surface.hit[:, order], 0, 1) & real[:, None, :]  # (b, k, width)
    n_c = np.where(hit_c[..., None], np.moveaxis(surface.normals[:, order], 0, 1), 0.0).sum(axis=2)
    norm = np.linalg.norm(n_c, axis=-1)
    rows = norm > 0
    n_c = n_c / np.where(norm > 0, norm, 1.0)[..., None]
    count = np.maximum(hit_c.sum(axis=2), 1)
    p_c = (
        np.where(hit_c[..., None], np.moveaxis(surface.points[:, order], 0, 1), 0.0).sum(axis=2)
        / count[..., None]
    )
    # The beam the step limits let the planner reach: pitch (in the u-w plane) and roll (the
    # rest) from the centre normal, each rate-limited along the pass.
    u, v = surface.u, surface.v
    beam = n_c.copy()
    shaped = np.flatnonzero(rows.sum(axis=1) >= 2)
    if len(shaped):
        along = surface.along_mm
        pitch_c, roll_c = aligning_angles(n_c[shaped], u, v)
        rs = rows[shaped]
        pitch = np.stack(
            [np.interp(along, along[r], p[r]) for r, p in zip(rs, pitch_c, strict=True)]
        )
        roll = np.stack([np.interp(along, along[r], p[r]) for r, p in zip(rs, roll_c, strict=True)])
        pitch = RobustLookahead().shape(along, pitch, PITCH_LEVER / wd)
        rate = ROLL_RATE * lim.dphi_max_rad / spec.delta_s_opt_mm
        roll = CentredLookahead().shape(along, roll, rate)
        # −z_s of those poses: from the surface towards the sensor (the normal, if aligned)
        z_s = frame_poses(np.zeros(3), u, v, 0 * pitch, 0 * pitch, pitch, roll)[:, :3, 2]
        beam[shaped] = -z_s.reshape(len(shaped), len(along), 3)
    offset = surface.points[None] - p_c[:, :, None, :]
    depth = np.abs(np.einsum("bkcj,bkj->bkc", offset, beam))
    angle_ok = np.einsum("kcj,bkj->bkc", surface.normals, beam) >= cos_tol
    ok = ~surface.hit[None] | ((depth <= tol_d) & angle_ok)
    ok &= (np.abs(across[None, :] - centres[:, None]) <= half_line)[:, None, :]
    # The centre itself must be in spec, else the row holds no band.
    ic = np.argmin(np.abs(across[None, :] - centres[:, None]), axis=1)
    at = np.arange(b)
    rows &= ok[at, :, ic] | ~surface.hit[:, ic].T
    # Walk out from the centre column: the first failing column bounds the band.
    out = (np.arange(cols)[None, :] - ic[:, None])[:, None, :]  # columns right of the centre
    bad = ~ok
    first_left = np.where(bad & (out <= 0), -out, cols).min(axis=2)
    first_left = np.minimum(first_left, ic[:, None] + 1)
    first_right = np.where(bad & (out >= 0), out, cols).min(axis=2)
    first_right = np.minimum(first_right, (cols - ic)[:, None])
    step = float(across[1] - across[0]) if cols > 1 else 1.0
    at_centre = across[ic][:, None]
    row_lo = np.where(rows, at_centre - (first_left - 0.5) * step, np.nan)
    row_hi = np.where(rows, at_centre + (first_right - 0.5) * step, np.nan)
    lo_edge = np.maximum(centres - half_line, float(across[0]) - step)
    hi_edge = np.minimum(centres + half_line, float(across[-1]) + step)
    row_lo = np.clip(row_lo, lo_edge[:, None], centres[:, None])
    row_hi = np.clip(row_hi, centres[:, None], hi_edge[:, None])
    # Nothing under the centre: the line is free to reach as far as it goes.
    lo = np.where(rows.any(axis=1), row_quantiles(row_lo, rows, 1.0 - row_quantile), lo_edge)
    hi = np.where(rows.any(axis=1), row_quantiles(row_hi, rows, row_quantile), hi_edge)
    return [
        Band(float(c), float(lo[i]), float(hi[i]), row_lo[i], row_hi[i])
        for i, c in enumerate(centres)
    ]


def row_quantiles(values: np.ndarray, keep: np.ndarray, q: float) -> np.ndarray:
    """(b,) the `q` quantile of each row of (b, k) `values` over its `keep` entries (NaN for a
    row with none), interpolated linearly as `np.quantile` does it, to the last bit (a call
    per row was a fifth of the bands' time)."""
    n = keep.sum(axis=1)
    ranked = np.sort(np.where(keep, values, np.inf), axis=1)  # kept entries first
    at = np.maximum(n - 1, 0) * q
    below = np.floor(at).astype(np.int64)
    last = at >= n - 1
    below = np.where(last, np.maximum(n - 1, 0), below)
    above = np.where(last, below, below + 1)
    a = np.take_along_axis(ranked, below[:, None], axis=1)[:, 0]
    b = np.take_along_axis(ranked, above[:, None], axis=1)[:, 0]
    t = at - below
    with np.errstate(invalid="ignore"):  # rows with nothing kept (inf - inf), NaN below
        diff = b - a
        out = np.where(t >= 0.5, b - diff * (1 - t), a + diff * t)
    return np.where(n > 0, out, np.nan)


def _covered_cells(surface: TopSurface, band: Band, edge_mm: float = 0.0) -> np.ndarray:
    """(k, c) bool: the surface cells inside the band's per-row edges, less `edge_mm` (at
    most a quarter of the row's band, so a narrow band on a small part still claims some)."""
    across = surface.across_mm[None, :]
    width = band.row_hi_mm - band.row_lo_mm
    with np.errstate(invalid="ignore"):
        edge = np.minimum(edge_mm, 0.25 * width)[:, None]
    lo, hi = band.row_lo_mm[:, None] + edge, band.row_hi_mm[:, None] - edge
    with np.errstate(invalid="ignore"):
        return surface.hit & (across >= lo) & (across <= hi)


def adaptive_offsets(
    surface: TopSurface,
    spec: ScanSpec,
    candidate_step_mm: float = 10.0,
    min_candidates: int = 24,
    min_gain: float = 0.005,
    max_passes: int = 60,
    edge_mm: float = 8.0,
) -> list[Band]:
    """Pass centres chosen greedily, set-cover style: among candidate centres every
    `candidate_step_mm` across the footprint (closer on a narrow part, so that there are
    at least `min_candidates`: its walls are narrow too), take the one whose predicted in-spec band
    covers the most surface not yet covered, until the next one would add less than
    `min_gain` of the surface. Curved parts get closer passes, flat ones fewer, and a strip
    no pass can hold in spec (a steep flange) does not pull in passes that add nothing.
    A band claims its cells less `edge_mm` at each edge, so neighbouring passes overlap
    (tracking and the camera's shadow blur a band's edge). Returned in order across the
    part (for the snake)."""
    cols = surface.hit.any(axis=0)
    if not cols.any():
        raise ValueError("the part has no surface a top-down raster can see")
    across = surface.across_mm
    first, last = float(across[cols][0]), float(across[cols][-1])
    step = min(candidate_step_mm, max((last - first) / min_candidates, 1e-3))
    centres = np.arange(first, last + step / 2, step)
    if len(centres) == 0:
        centres = np.array([0.5 * (first + last)])
    bands = in_spec_bands(surface, centres, spec)
    cells = np.stack([_covered_cells(surface, b, edge_mm).ravel() for b in bands])
    # A cell stands for its surface area, not its plan area: a 70° wall holds 3× its cell.
    cos_steep = math.cos(math.radians(COVERAGE_MAX_SLOPE_DEG))
    area = np.where(surface.hit, 1.0 / np.maximum(surface.normals[..., 2], cos_steep), 0.0)
    area = area.ravel()
    total = max(float(area.sum()), 1.0)
    covered = np.zeros(cells.shape[1], bool)
    chosen: list[int] = []
    while len(chosen) < max_passes:
        gain = (cells & ~covered) @ area
        best = int(np.argmax(gain))
        if chosen and gain[best] < min_gain * total:
            break
        if gain[best] == 0:  # nothing can be held in spec: one pass over the middle
            best = len(centres) // 2 if not chosen else best
            if chosen:
                break
        chosen.append(best)
        covered |= cells[best]
    return [bands[i] for i in sorted(chosen)]


def plan_adaptive_swaths(
    part: Part,
    spec: ScanSpec,
    direction: str | np.ndarray | DirectionRule = "auto",
    run_in_mm: float = 20.0,
    uphill: np.ndarray | None = None,
) -> list[Swath]:
    """Passes that adapt to the surface (none downhill toward a table, `swaths.swaths_at`):
    pass centres chosen so that their predicted in-spec bands (`in_spec_bands`) cover the
    surface (a greedy set cover, `adaptive_offsets`); the band goes with the swath
    (`Swath.band_mm`) so planners align the line to it. The direction rule is the nominal
    raster's ('auto': less variation across the line): ranking the two directions by
    predicted in-spec coverage picked the worse one on two of three real parts
    (benchmarks/compare_planners.py)."""
    u = scan_direction(part, spec.sensor, direction)
    surface = top_surface(part, u, np.cross(UP, u), sensor_above_mm=spec.working_distance_mm)
    if part.occluders and not surface.hit.any():
        raise ValueError("the fixtures (--fixture) hide all the surface a top-down raster sees")
    bands = adaptive_offsets(surface, spec)
    offsets = [b.centre_mm for b in bands]
    rel = [(b.lo_mm - b.centre_mm, b.hi_mm - b.centre_mm) for b in bands]
    return swaths_at(part, spec.sensor, u, offsets, rel, run_in_mm, True, uphill)
