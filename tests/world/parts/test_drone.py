"""The drone: a raised canopy on a rounded hull."""

from __future__ import annotations

import numpy as np

from scanplan.world.parts import build_part


def test_drone_has_a_raised_canopy_on_a_rounded_hull():
    mesh = build_part("drone")
    v = mesh.vertices
    top = v[v[:, 2] > 0.5]
    assert top[np.hypot(top[:, 0] + 15.0, top[:, 1]) < 10.0, 2].min() > 60.0
    assert top[np.abs(top[:, 0] - 150.0) < 3.0, 2].max() < 45.0
    # round footprint: no vertex near the bounding box corners
    assert not np.any((np.abs(v[:, 0]) > 150.0) & (np.abs(v[:, 1]) > 40.0))
