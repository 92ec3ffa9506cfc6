"""The surface to inspect (surface.py): what the upper hemisphere sees beyond a top-down raster."""

from __future__ import annotations

import math

import pytest

from helpers import sloped_housing
from scanplan.surface import hemisphere_visible_samples, upward_visible_samples


def test_hemisphere_surface_adds_what_only_a_tilted_view_sees(housing):
    # 60° walls are within the top view's 80° slope limit: both surfaces hold them.
    part = housing
    up, hemi = upward_visible_samples(part, 2.0), hemisphere_visible_samples(part, 2.0)
    assert hemi.area_mm2 == pytest.approx(up.area_mm2, rel=0.01)
    # 85° walls: only the hemisphere's tilted directions see them.
    steep = sloped_housing(slope_deg=85.0)
    up, hemi = upward_visible_samples(steep, 2.0), hemisphere_visible_samples(steep, 2.0)
    walls = 2 * (600 + 400) * 150 / math.sin(math.radians(85.0))
    assert hemi.area_mm2 == pytest.approx(up.area_mm2 + walls, rel=0.03)
