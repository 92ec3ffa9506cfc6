"""The door: its bulge, handle pocket and character line, and the skin that is inspected."""

from __future__ import annotations

import numpy as np
import pytest

from scanplan.world.parts import build_part


def test_door_has_its_features():
    mesh = build_part("door")
    v = mesh.vertices
    top = v[v[:, 2] > 1.0]
    # convex bulge: the middle stands well above the edges
    centre = top[np.hypot(top[:, 0], top[:, 1] - 50.0) < 60.0, 2].mean()
    edge = top[np.abs(top[:, 0]) > 715.0, 2].mean()
    assert centre - edge > 50.0
    # handle pocket ~20 mm deep against the skin around it
    pocket = top[(np.abs(top[:, 0] - 480.0) < 40.0) & (np.abs(top[:, 1] - 70.0) < 10.0), 2]
    around = top[(np.abs(top[:, 0] - 480.0) < 40.0) & (np.abs(top[:, 1] - 70.0 + 50.0) < 3.0), 2]
    assert around.mean() - pocket.mean() == pytest.approx(20.0, abs=6.0)
    # character line: the slope dz/dy jumps across y = 120 mm
    col = top[np.abs(top[:, 0] - 0.0) < 1e-6]
    col = col[np.argsort(col[:, 1])]
    dzdy = np.diff(col[:, 2]) / np.diff(col[:, 1])
    mid = (col[1:, 1] + col[:-1, 1]) / 2
    below = dzdy[(mid > 110.0) & (mid < 118.0)].mean()
    above = dzdy[(mid > 122.0) & (mid < 130.0)].mean()
    assert np.degrees(np.arctan(below) - np.arctan(above)) > 5.0


def test_the_door_inspects_its_skin_not_the_solid_sides(door):
    from scanplan.world.part import load_part

    assert door.inspect_faces is not None
    normals = door.mesh.face_normals
    assert (normals[door.inspect_faces, 2] > 0).all()
    sides = np.abs(normals[:, 2]) < 1e-6
    assert sides.any() and not door.inspect_faces[sides].any()
    assert load_part("drone").inspect_faces is None
