"""Adaptive pass placement (bands.plan_adaptive_swaths): passes spaced by the band of the line
that stays in spec, rolled onto a curved surface (SPEC §3b)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from scanplan.core.quantities import ScanSpec
from scanplan.judging import evaluate
from scanplan.planning import bands
from scanplan.planning.bands import plan_adaptive_swaths, row_quantiles, top_surface
from scanplan.planning.pass_path import plan_path
from scanplan.planning.planners.geometric import GeometricPlanner
from scanplan.planning.swaths import plan_swaths
from scanplan.world.part import part_from_mesh

SPEC = ScanSpec()


def half_cylinder_part(radius: float = 150.0, length: float = 600.0):
    cyl = trimesh.creation.cylinder(radius=radius, height=length, sections=256)
    cyl.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [0, 1, 0]))
    return part_from_mesh(cyl, "cylinder")


@pytest.mark.slow
def test_horizontal_cylinder_adaptive_passes_with_roll_cover_its_upper_half():
    """R = 150 mm, axis along x, scanned along the axis. The band a pass holds in spec spans
    about ±10° of the surface (the 15° tolerance with margin) and claims a little less (its
    edges overlap the neighbours'), so covering the upper half to the 80° of the coverage
    definition takes rolls from about −75° to +75° and some 10-16 passes; a nominal raster
    with pitch only is one pass, in spec only near the top."""
    part = half_cylinder_part()
    adaptive = plan_adaptive_swaths(part, SPEC, "x")
    traj = plan_path(part, SPEC, GeometricPlanner.with_roll(), adaptive)
    m = evaluate(part, SPEC, traj, points_per_profile=512)
    rolls = [
        math.degrees(math.asin(traj.poses[traj.swath == s.index][len(traj.poses) // 100, 1, 2]))
        for s in adaptive
    ]
    assert 8 <= len(adaptive) <= 16
    assert max(rolls) > 55.0 and min(rolls) < -55.0
    assert m.in_spec_coverage >= 0.9
    nominal = plan_path(part, SPEC, GeometricPlanner(), plan_swaths(part, SPEC.sensor, "x"))
    assert evaluate(part, SPEC, nominal, points_per_profile=256).in_spec_coverage < 0.4


def test_row_quantiles_are_numpys_to_the_last_bit():
    rng = np.random.default_rng(2)
    values = rng.normal(0.0, 50.0, (300, 40))
    keep = rng.random((300, 40)) < rng.uniform(0.02, 1.0, (300, 1))
    keep[:3] = False  # rows with nothing kept
    for q in (0.0, 0.15, 0.5, 0.85, 1.0):
        got = row_quantiles(values, keep, q)
        want = [
            np.quantile(v[k], q) if k.any() else np.nan for v, k in zip(values, keep, strict=True)
        ]
        np.testing.assert_array_equal(got, want)


def test_bands_of_many_centres_are_each_centres_band(monkeypatch):
    """The pass centres of a raster predicted in batches (here of a few centres, so that one
    call makes several) are the bands each centre alone gets, and they differ from one
    another (the cylinder's curvature narrows the band away from its crest)."""
    part = half_cylinder_part()
    surface = top_surface(part, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    centres = np.arange(-140.0, 141.0, 10.0)
    monkeypatch.setattr(bands, "BAND_BATCH_CELLS", 4 * surface.hit.size)
    many = bands.in_spec_bands(surface, centres, SPEC)
    for centre, band in zip(centres, many, strict=True):
        alone = bands.in_spec_bands(surface, np.array([centre]), SPEC)[0]
        assert (band.centre_mm, band.lo_mm, band.hi_mm) == (
            alone.centre_mm,
            alone.lo_mm,
            alone.hi_mm,
        )
        np.testing.assert_array_equal(band.row_lo_mm, alone.row_lo_mm)
        np.testing.assert_array_equal(band.row_hi_mm, alone.row_hi_mm)
    widths = [b.hi_mm - b.lo_mm for b in many]
    assert max(widths) > 2 * min(widths)
