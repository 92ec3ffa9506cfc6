"""Adaptive pass placement (bands.plan_adaptive_swaths): passes spaced by the band of the line
that stays in spec, rolled onto a curved surface (SPEC §3b)."""

from __future__ import annotations

import math

import pytest
import trimesh

from scanplan.bands import plan_adaptive_swaths
from scanplan.metrics import evaluate
from scanplan.part import part_from_mesh
from scanplan.pipeline import plan_path
from scanplan.planners.geometric import GeometricPlanner
from scanplan.quantities import ScanSpec
from scanplan.swaths import plan_swaths

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
