"""A placed arm as the view choice asks it: what it could reach of a view's samples."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from scanplan.core.context import PlanContext
from scanplan.core.quantities import UP, ScanSpec
from scanplan.robot.export import parse_pose_arg
from scanplan.robot.placed_arm import NOMINAL_TURNS, PlacedArm
from scanplan.robot.presets import get_robot
from scanplan.robot.reach import fit_limits

TCP = parse_pose_arg("0,0,90,0,0,0")


def _within_limits(robot: str, T_base_flange: np.ndarray) -> np.ndarray:
    """(n,) whether some IK branch of each pose lies within the arm's joint limits."""
    arm = get_robot(robot)
    q = arm.inverse(T_base_flange)
    _, inside = fit_limits(q, arm.joint_limits)
    return (inside & ~np.isnan(q).any(axis=-1)).any(axis=-1)


def test_the_arm_reaches_a_point_when_a_sensor_turned_about_the_beam_over_it_is_in_reach():
    T_base_part = parse_pose_arg("450,0,-200,0,0,0")
    arm = PlacedArm("ur5e", TCP, T_base_part, PlanContext(ScanSpec()))
    # Where it stands: the base's origin in the part's frame.
    assert np.allclose(T_base_part @ np.r_[arm.stands_at, 1.0], [0, 0, 0, 1])
    rng = np.random.default_rng(3)
    points = rng.uniform([-1500, -1200, -100], [900, 1200, 300], size=(400, 3))
    got = arm.reaches(points, UP)
    assert 0.1 < got.mean() < 0.9  # some in reach, some not: the test below can fail
    # Built here another way: the sensor over each point, looking down, at the working
    # distance, turned about its beam by each quarter turn.
    wd = ScanSpec().working_distance_mm
    expected = np.zeros(len(points), bool)
    for k in range(NOMINAL_TURNS):
        R = Rotation.from_euler("zx", [360.0 * k / NOMINAL_TURNS, 180.0], degrees=True)
        sensor = np.broadcast_to(np.eye(4), (len(points), 4, 4)).copy()
        sensor[:, :3, :3] = R.as_matrix()
        sensor[:, :3, 3] = points + [0.0, 0.0, wd]
        expected |= _within_limits("ur5e", T_base_part @ sensor @ np.linalg.inv(TCP))
    np.testing.assert_array_equal(got, expected)
    # Three metres off: nothing.
    assert not arm.reaches(points[:20] + [3000.0, 0.0, 0.0], UP).any()
