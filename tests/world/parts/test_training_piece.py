"""The training piece: ramps of several slopes, steps up and down inside, a cross-sloped bump."""

from __future__ import annotations

import numpy as np
import pytest

from scanplan.world.parts import build_part, training_piece


def _top_tilts_deg(mesh):
    """Tilt from +Z of each upward face, and its area."""
    n = mesh.face_normals
    up = n[:, 2] > 0.05
    return np.degrees(np.arccos(np.clip(n[up, 2], -1, 1))), mesh.area_faces[up], n[up]


def test_training_piece_has_ramps_of_several_slopes():
    tilt, area, _ = _top_tilts_deg(build_part("training-piece"))
    bins = np.round(tilt * 2) / 2  # 0.5° bins
    planar = {b for b in np.unique(bins) if b >= 1.0 and area[bins == b].sum() > 2000.0}
    assert len(planar) >= 4
    for slope in (10.0, 20.0, 30.0, 45.0):
        ramp_area = area[np.abs(tilt - slope) < 0.05].sum()
        assert ramp_area > 150.0 * 5.0, f"no {slope}° ramp"
    flat_area = area[tilt < 0.01].sum()
    assert flat_area > 0.3 * 1050 * 150


def test_training_piece_volume_is_its_profile_times_width():
    x, z, _ = training_piece.profile()
    area_mm2 = np.sum(np.diff(x) * (z[1:] + z[:-1]) / 2)
    assert build_part("training-piece").volume == pytest.approx(150.0 * area_mm2, rel=1e-3)


def test_training_piece_has_vertical_steps_up_and_down_inside():
    mesh = build_part("training-piece")
    n, centre = mesh.face_normals, mesh.triangles_center
    inside = np.abs(centre[:, 0]) < 524.0
    for sign in (1, -1):
        riser = inside & (sign * n[:, 0] > 0.9999)
        assert mesh.area_faces[riser].sum() >= 150.0 * 10.0, f"no step facing {sign:+d}X"
        # a riser spans the full width of the piece
        assert np.ptp(centre[riser, 1]) > 140.0


def test_training_piece_top_heights_and_roll_feature():
    mesh = build_part("training-piece")
    _, _, n = _top_tilts_deg(mesh)
    top = mesh.vertices[mesh.vertices[:, 2] > 1.0]
    assert top[:, 2].min() == pytest.approx(15.0, abs=1.0)
    assert top[:, 2].max() == pytest.approx(50.0)
    # the cross-sloped bump: upward faces that lean sideways (roll), by more than a degree
    roll = np.degrees(np.arctan2(np.abs(n[:, 1]), n[:, 2]))
    assert roll.max() > 1.0
    assert roll.max() < 15.0
