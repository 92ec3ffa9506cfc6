"""A view's poses moved as a whole: beams turned about their footprints, lines slid."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from scanplan.core.quantities import UP, ScanSpec
from scanplan.planning.view_poses import limit_beam_tilt, raised_beams, slid_lines
from scanplan.world.surface import VIEW_AXIS_MAX_TILT_DEG

SPEC = ScanSpec()


def test_a_beam_leaning_past_the_view_tilt_is_turned_back_about_its_footprint():
    wd = SPEC.working_distance_mm
    level = np.eye(4)
    level[:3, :3] = Rotation.from_euler("y", 90, degrees=True).as_matrix()  # beam along +x
    level[:3, 3] = (-wd, 0.0, 30.0)
    down = np.eye(4)
    down[:3, :3] = Rotation.from_euler("x", 180, degrees=True).as_matrix()  # beam along -z
    out = limit_beam_tilt(np.stack([level, down]), UP, wd)
    tilt = math.degrees(math.acos(-out[0, 2, 2]))
    assert tilt == pytest.approx(VIEW_AXIS_MAX_TILT_DEG)
    assert np.allclose(out[0, :3, 3] + wd * out[0, :3, 2], (0.0, 0.0, 30.0))  # same footprint
    assert out[0, 2, 3] > 30.0 + 60.0  # the sensor lifted above the footprint
    assert np.allclose(out[0, :3, 0] @ out[0, :3, 1], 0.0)
    assert np.array_equal(out[1], down)  # a beam within the tilt is left as it was


def test_beams_raised_keep_their_footprints_and_a_beam_near_straight_down_goes_no_further():
    wd = SPEC.working_distance_mm
    side = np.eye(4)
    side[:3, :3] = Rotation.from_euler("y", 80, degrees=True).as_matrix()  # 10 deg below level
    side[:3, 3] = (-wd, 0.0, 30.0)
    steep = np.eye(4)
    steep[:3, :3] = Rotation.from_euler("y", 178, degrees=True).as_matrix()  # 2 deg off down
    out = raised_beams(np.stack([side, steep]), wd, 4.0)
    down = np.array([0.0, 0.0, -1.0])
    before = [math.degrees(math.acos(p[:3, 2] @ down)) for p in (side, steep)]
    after = [math.degrees(math.acos(np.clip(p[:3, 2] @ down, -1, 1))) for p in out]
    assert after[0] == pytest.approx(before[0] - 4.0)
    assert after[1] == pytest.approx(0.0, abs=1e-6)  # turned onto straight down, not past it
    for p, q in zip((side, steep), out, strict=True):
        assert np.allclose(p[:3, 3] + wd * p[:3, 2], q[:3, 3] + wd * q[:3, 2])  # same footprint
        assert np.allclose(q[:3, :3] @ q[:3, :3].T, np.eye(3))
    assert out[0, 2, 3] > side[2, 3]  # seen from higher up


def test_lines_slide_along_themselves_each_pass_towards_the_point():
    down = Rotation.from_euler("x", 180, degrees=True).as_matrix()  # beam -z, line +x
    poses = np.broadcast_to(np.eye(4), (4, 4, 4)).copy()
    poses[:, :3, :3] = down
    poses[:, :3, 3] = [
        (0.0, 0.0, 400.0),
        (0.0, 10.0, 400.0),
        (500.0, 0.0, 400.0),
        (500.0, 10.0, 400.0),
    ]
    swath = np.array([0, 0, 1, 1])
    # The point at x = 300: the first pass slides +x towards it, the second -x.
    out = slid_lines(poses, swath, np.array([300.0, 0.0, 0.0]), 50.0)
    assert np.allclose(out[:, 0, 3], [50.0, 50.0, 450.0, 450.0])
    assert np.allclose(out[:, 1:3, 3], poses[:, 1:3, 3])  # only along the line
    assert np.array_equal(out[:, :3, :3], poses[:, :3, :3])  # beams and lines as they were
    # A pass whose poses lie either side of the point goes the way most of it is nearer.
    mixed = poses.copy()
    mixed[:, 0, 3] = [290.0, 250.0, 0.0, 0.0]
    both = slid_lines(mixed, np.array([0, 0, 1, 1]), np.array([300.0, 0.0, 0.0]), 5.0)
    assert np.allclose(both[:2, 0, 3], [295.0, 255.0])
