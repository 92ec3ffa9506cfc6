"""Passes that adapt to the surface (SPEC §3b): the band of the laser line that stays in spec.

A 495 mm line on a curved part is in spec (|z_s − W_d| ≤ tol_d, α_i ≤ tol_α) only on a band
around where the beam is aligned with the surface. `in_spec_band` predicts that band for a
pass centred at a lateral offset, from the CAD's top surface (vertical rays on a grid), with
the beam aligned — by pitch and roll — to the surface normal at the band's centre.
`adaptive_offsets` sweeps across the part placing passes so that consecutive bands overlap:
curved parts get closer passes, flat ones fewer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scanplan.part import Part
from scanplan.quantities import ScanSpec

UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class TopSurface:
    """The part's top surface seen from above on a grid in the raster's (u, v) frame.

    along_mm: (k,) and across_mm: (c,) grid coordinates; hit: (k, c); points: (k, c, 3) part
    frame; normals: (k, c, 3) unit, facing up (0 where no hit).
    """

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
) -> TopSurface:
    """Vertical rays on a grid over the part's footprint along u and v (one batch)."""
    vertices = np.asarray(part.mesh.vertices)
    a, c = vertices @ u, vertices @ v
    along = np.arange(a.min() + along_step_mm / 2, a.max(), along_step_mm)
    if len(along) == 0:
        along = np.array([0.5 * (a.min() + a.max())])
    across = np.arange(c.min(), c.max() + across_step_mm, across_step_mm)
    top = float(part.bounds[1, 2]) + 10.0
    xy = along[:, None, None] * u + across[None, :, None] * v
    origins = xy.reshape(-1, 3).copy()
    origins[:, 2] = top
    t, face, normals = part.ray_engine.cast_down(origins)
    shape = (len(along), len(across))
    hit = (face >= 0).reshape(shape)
    points = origins.reshape(*shape, 3).copy()
    points[..., 2] = top - np.where(hit, t.reshape(shape), 0.0)
    return TopSurface(along, across, hit, points, normals.reshape(*shape, 3))


@dataclass(frozen=True)
class Band:
    """The predicted in-spec band of a pass centred at `centre_mm` (along v): [lo, hi] along v
    (part frame), and per grid row the edges (NaN for rows without surface at the centre)."""

    centre_mm: float
    lo_mm: float
    hi_mm: float
    row_lo_mm: np.ndarray
    row_hi_mm: np.ndarray


def in_spec_band(
    surface: TopSurface,
    centre_mm: float,
    spec: ScanSpec,
    margin: float = 0.7,
    centre_halfwidth_mm: float = 15.0,
    row_quantile: float = 0.15,
) -> Band:
    """The band around `centre_mm` where the surface would be in spec with the beam aligned to
    the mean normal near the centre, W_d from the centre point, per grid row; the pass's band
    is a robust envelope over the rows (`row_quantile` of the rows may be narrower: a local
    feature must not shrink a whole pass). `margin` scales both tolerances: tracking under
    the step limits and the one pitch per station leave less than the full tolerance.
    Columns without surface count as in spec (nothing there to measure)."""
    tol_d = margin * spec.tolerance_mm
    cos_tol = math.cos(margin * spec.tol_angle_rad)
    half_line = spec.sensor.line_width_mm / 2
    across = surface.across_mm
    near = np.abs(across - centre_mm) <= centre_halfwidth_mm
    hit_c = surface.hit[:, near]
    n_c = np.where(hit_c[..., None], surface.normals[:, near], 0.0).sum(axis=1)
    norm = np.linalg.norm(n_c, axis=1)
    rows = norm > 0
    n_c = n_c / np.where(norm > 0, norm, 1.0)[:, None]
    count = np.maximum(hit_c.sum(axis=1), 1)
    p_c = np.where(hit_c[..., None], surface.points[:, near], 0.0).sum(axis=1) / count[:, None]
    offset = surface.points - p_c[:, None, :]
    depth = np.abs(np.einsum("kcj,kj->kc", offset, n_c))
    angle_ok = np.einsum("kcj,kj->kc", surface.normals, n_c) >= cos_tol
    ok = ~surface.hit | ((depth <= tol_d) & angle_ok)
    ok &= (np.abs(across - centre_mm) <= half_line)[None, :]
    # Walk out from the centre column: the first failing column bounds the band.
    ic = int(np.argmin(np.abs(across - centre_mm)))
    bad_left = ~ok[:, : ic + 1][:, ::-1]
    bad_right = ~ok[:, ic:]
    first_left = np.where(bad_left.any(axis=1), bad_left.argmax(axis=1), bad_left.shape[1])
    first_right = np.where(bad_right.any(axis=1), bad_right.argmax(axis=1), bad_right.shape[1])
    step = float(across[1] - across[0]) if len(across) > 1 else 1.0
    row_lo = np.where(rows, across[ic] - (first_left - 0.5) * step, np.nan)
    row_hi = np.where(rows, across[ic] + (first_right - 0.5) * step, np.nan)
    lo_edge = max(centre_mm - half_line, float(across[0]) - step)
    hi_edge = min(centre_mm + half_line, float(across[-1]) + step)
    row_lo = np.clip(row_lo, lo_edge, centre_mm)
    row_hi = np.clip(row_hi, centre_mm, hi_edge)
    if rows.any():
        lo = float(np.quantile(row_lo[rows], 1.0 - row_quantile))
        hi = float(np.quantile(row_hi[rows], row_quantile))
    else:  # nothing under the centre: the line is free to reach as far as it goes
        lo, hi = lo_edge, hi_edge
    return Band(centre_mm, lo, hi, row_lo, row_hi)


def adaptive_offsets(
    surface: TopSurface, spec: ScanSpec, overlap: float = 0.1, max_passes: int = 60
) -> list[Band]:
    """Pass centres across the footprint, each as far on as its band allows while its lower
    edge still overlaps the previous band's upper edge by `overlap` of the band width; the
    first band reaches the footprint's near edge, the last its far edge."""
    cols = surface.hit.any(axis=0)
    if not cols.any():
        raise ValueError("the part has no surface a top-down raster can see")
    across = surface.across_mm
    first, last = float(across[cols][0]), float(across[cols][-1])
    half_line = spec.sensor.line_width_mm / 2
    step = max(float(across[1] - across[0]) if len(across) > 1 else 1.0, 2.0)
    bands: list[Band] = []
    reach = first  # the band's lower edge must reach here
    while len(bands) < max_passes:
        candidates = np.arange(reach, min(reach + half_line, last + half_line) + step, step)
        best: Band | None = None
        for c in candidates:
            band = in_spec_band(surface, float(c), spec)
            if band.lo_mm <= reach + 1e-9:
                best = band  # the furthest centre whose band still reaches back
        if best is None:  # even a band centred on the edge does not reach it: advance anyway
            best = in_spec_band(surface, float(reach), spec)
        bands.append(best)
        if best.hi_mm >= last - 1e-9:
            break
        width = best.hi_mm - best.lo_mm
        reach = max(best.hi_mm - overlap * width, best.centre_mm + step)
    return bands


def predicted_in_spec(surface: TopSurface, bands: list[Band]) -> float:
    """Fraction of the grid's surface cells inside some pass's per-row band: the in-spec
    coverage these passes are expected to reach (ranks scan directions)."""
    covered = np.zeros(surface.hit.shape, bool)
    across = surface.across_mm[None, :]
    for band in bands:
        lo, hi = band.row_lo_mm[:, None], band.row_hi_mm[:, None]
        covered |= (across >= lo) & (across <= hi)
    return float(covered[surface.hit].mean()) if surface.hit.any() else 0.0
