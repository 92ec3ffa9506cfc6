"""Boustrophedon base path: pass count, direction, snake order, transitions (SPEC §3)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import trimesh

from scanplan.core.quantities import UP
from scanplan.core.sensor_spec import SensorSpec
from scanplan.planning.swaths import Swath, plan_swaths, swath_from_record, swath_record
from scanplan.world.part import part_from_mesh

SENSOR = SensorSpec()
W = SENSOR.line_width_mm  # 495 mm


def plate(length: float, width: float, angle_deg: float = 0.0, offset=(0.0, 0.0, 0.0)):
    mesh = trimesh.creation.box((length, width, 10.0))
    mesh.apply_transform(trimesh.transformations.rotation_matrix(math.radians(angle_deg), UP))
    mesh.apply_translation(offset)
    return part_from_mesh(mesh, "plate")


@pytest.mark.parametrize("width", [100.0, 400.0, 494.0, 600.0, 1000.0, 1500.0])
def test_pass_count_matches_the_analytic_count(width):
    step = W * (1 - 0.2)
    expected = 1 if width <= W else 1 + math.ceil((width - W) / step)
    swaths = plan_swaths(plate(2000.0, width), SENSOR, "x", 0.2)
    assert len(swaths) == expected
    # Centred on the footprint, and together the lines cover it.
    offsets = np.array([s.start_mm[1] for s in swaths])
    assert offsets.mean() == pytest.approx(0.0, abs=1e-6)
    assert offsets.min() - W / 2 <= -width / 2 + 1e-6
    assert offsets.max() + W / 2 >= width / 2 - 1e-6


def test_narrow_plate_gets_one_straight_pass_along_its_centre():
    (swath,) = plan_swaths(plate(350.0, 95.0), SENSOR)
    assert swath.start_mm[1] == pytest.approx(0.0)
    assert swath.length_mm == pytest.approx(350.0 + 2 * 20.0)
    assert swath.start_mm[2] == pytest.approx(5.0 + SENSOR.working_distance_mm)


def test_rotated_off_origin_part_auto_direction_finds_the_long_axis():
    part = plate(1200.0, 700.0, angle_deg=30.0, offset=(500.0, -300.0, 40.0))
    swaths = plan_swaths(part, SENSOR, "auto")
    long_axis = np.array([math.cos(math.radians(30)), math.sin(math.radians(30)), 0.0])
    assert abs(np.dot(swaths[0].u, long_axis)) == pytest.approx(1.0, abs=1e-6)
    assert len(swaths) == 1 + math.ceil((700.0 - W) / (0.8 * W))
    # The passes span the part along u (plus run-in) around its centre.
    mids = np.array([(s.start_mm + s.end_mm) / 2 for s in swaths])
    assert mids[:, :2].mean(axis=0) == pytest.approx([500.0, -300.0], abs=1e-3)
    assert swaths[0].length_mm == pytest.approx(1200.0 + 40.0, abs=1e-3)


def test_snake_order_alternates_direction():
    swaths = plan_swaths(plate(1000.0, 1500.0), SENSOR, "x")
    for a, b in zip(swaths, swaths[1:], strict=False):
        assert np.dot(a.u, b.u) == pytest.approx(-1.0)
        assert np.linalg.norm(a.end_mm[:2] - b.start_mm[:2]) < np.linalg.norm(
            a.start_mm[:2] - b.start_mm[:2]
        )


def test_pose_pitch_convention_and_inverse():
    (swath,) = plan_swaths(plate(300.0, 100.0), SENSOR)
    pose = swath.pose(12.0, -3.0, math.radians(10))
    # theta > 0 tilts the beam towards -u.
    assert np.dot(pose[:3, 2], swath.u) < 0
    s, h, th = swath.to_swath_frame(pose)
    assert (s, h, th) == pytest.approx((12.0, -3.0, math.radians(10)))


def test_auto_direction_scans_across_curvature_a_pitch_only_planner_cannot_follow(door):
    """The door bulges across its width: passes along its length would leave ~20 mm of
    cross-line height variation, passes across it ~4 mm. A training piece varies only along
    its length, so it is scanned lengthwise."""
    from scanplan.planning.swaths import cross_line_residual_mm, scan_direction
    from scanplan.world.part import load_part

    sensor = SensorSpec()
    width = sensor.line_width_mm
    assert np.allclose(np.abs(scan_direction(door, sensor, "long")), [1, 0, 0], atol=1e-6)
    assert np.allclose(np.abs(scan_direction(door, sensor, "auto")), [0, 1, 0], atol=1e-6)
    along_x = cross_line_residual_mm(door, np.array([1.0, 0, 0]), width)
    along_y = cross_line_residual_mm(door, np.array([0.0, 1, 0]), width)
    assert along_y < 0.5 * along_x
    piece = load_part("training-piece")
    assert np.allclose(np.abs(scan_direction(piece, sensor, "auto")), [1, 0, 0], atol=1e-6)


def test_a_pass_line_record_reads_back_exactly_and_bad_ones_are_named():
    u = np.array([0.6, 0.8, 0.0])
    sw = Swath(
        3,
        np.array([0.1, -2.0 / 3.0, 400.0]),
        np.array([5.0, 1.0, 400.0]),
        u,
        np.cross(UP, u),
        (-1.5, 2.25),
    )
    back = swath_from_record(json.loads(json.dumps(swath_record(sw, 7))), "plan")
    assert back.index == 7 and back.band_mm == sw.band_mm
    for key in ("start_mm", "end_mm", "u", "v"):
        assert np.array_equal(getattr(back, key), getattr(sw, key))
    for bad, message in [
        ([], "plan: expected a JSON object"),
        ({**swath_record(sw), "u": [1.0, 0.0]}, r"plan.u: List should have at least 3"),
        ({**swath_record(sw), "u": [2.0, 0.0, 0.0]}, r"plan: u \[2.0, 0.0, 0.0\] is not a unit"),
        ({**swath_record(sw), "v": [0.8, -0.6, 0.0]}, "plan: v .* is not up x u"),
        ({**swath_record(sw), "start_mm": "here"}, "plan.start_mm: Input should be a valid list"),
        ({**swath_record(sw), "end_mm": [1e300, 0, 0]}, r"plan.end_mm\[0\]: 1e\+300 is not in"),
        # A 10 km pass is out of the part's frame; one of 150 m in it is still too long (a
        # closed loop steps along all of it): both refused before any work.
        ({**swath_record(sw), "end_mm": [6e6, 8e6, 400]}, r"plan.end_mm\[0\]: 6000000 is not"),
        (
            {**swath_record(sw), "start_mm": [-9e4, -9e4, 400], "end_mm": [0, 3e4, 400]},
            r"plan: its length 150000 is not in \[0, 100000\] mm",
        ),
        ({**swath_record(sw), "band_mm": [2.0, -1.0]}, "plan: band_mm .* runs backwards"),
        ({**swath_record(sw), "index": -1}, "plan.index: Input should be greater than"),
    ]:
        with pytest.raises(ValueError, match=f"^{message}"):
            swath_from_record(bad, "plan")
