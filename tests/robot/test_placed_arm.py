"""A placed arm as the view choice asks it: what it could reach of a view's samples."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

import scanplan.robot.flown_poses as flown_poses
from helpers import plate_with_block
from scanplan.core.context import PlanContext
from scanplan.core.quantities import UP, ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.robot.export import parse_pose_arg
from scanplan.robot.nearest_joints import fit_limits
from scanplan.robot.placed_arm import NOMINAL_TURNS, PlacedArm
from scanplan.robot.presets import get_robot

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


def test_the_shoulder_is_where_the_upper_arm_starts_in_the_parts_frame():
    # The part 500 mm out along the base's x and turned a quarter turn about its z.
    T_base_part = np.eye(4)
    T_base_part[:3, :3] = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    T_base_part[:3, 3] = (500.0, 0.0, 0.0)
    for robot, height in (("kr6-r900", 400.0), ("irb2400", 615.0)):
        arm = PlacedArm(robot, np.eye(4), T_base_part, PlanContext(ScanSpec()))
        in_base = T_base_part @ np.r_[arm.shoulder_at, 1.0]
        assert np.isclose(in_base[2], height)  # the upper arm's first joint above the base
        assert 0.0 < in_base[0] < 150.0 and abs(in_base[1]) < 1e-9  # a little ahead of joint 1
        assert np.allclose(arm.stands_at, np.linalg.inv(T_base_part)[:3, 3])


def test_moves_are_clear_unless_one_brings_the_sensor_body_into_the_part():
    part = plate_with_block()
    wd = ScanSpec().working_distance_mm
    down = Rotation.from_euler("x", 180, degrees=True).as_matrix()  # looking down
    poses = np.broadcast_to(np.eye(4), (3, 4, 4)).copy()
    poses[:, :3, :3] = down
    top = float(part.bounds[1, 2])
    poses[:, :3, 3] = [(0.0, 0.0, top + wd), (20.0, 0.0, top + wd), (40.0, 0.0, top + wd)]
    traj = Trajectory(poses, np.zeros(3, int), np.array([False, True, True]))
    arm = PlacedArm("kr6-r900", TCP, parse_pose_arg("500,0,0,0,0,0"), PlanContext(ScanSpec()))
    assert arm.moves_clear(part, traj)
    inside = poses.copy()
    inside[0, :3, 3] = part.bounds.mean(axis=0)  # the move's pose in the middle of the part
    assert not arm.moves_clear(part, Trajectory(inside, traj.swath, traj.scanning))
    # A scanning pose there is not a move's: `flown` judges it.
    scanning_inside = Trajectory(inside, traj.swath, np.ones(3, bool))
    assert arm.moves_clear(part, scanning_inside)


def test_flown_beyond_is_what_flown_keeps_when_more_and_asks_no_link_when_it_cannot_be(
    monkeypatch,
):
    part = plate_with_block()
    wd = ScanSpec().working_distance_mm
    down = Rotation.from_euler("x", 180, degrees=True).as_matrix()
    top = float(part.bounds[1, 2])
    poses, swath, scanning = [], [], []
    for k, y in enumerate((-150.0, 0.0, 150.0)):
        for x in np.linspace(-450.0, 450.0, 31):
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = down, (x, y, top + wd)
            poses.append(T)
            swath.append(k)
            scanning.append(True)
    traj = Trajectory(np.array(poses), np.array(swath), np.array(scanning))
    arm = PlacedArm("kr6-r900", TCP, parse_pose_arg("650,0,-400,0,0,0"), PlanContext(ScanSpec()))
    flown = arm.flown(part, traj)
    kept = int(flown.scanning.sum())
    assert 0 < kept < len(traj)  # the far ends are out of reach: both answers can be met
    more = arm.flown_beyond(part, traj, kept - 1)
    assert more is not None
    np.testing.assert_array_equal(more.poses, flown.poses)
    assert arm.flown_beyond(part, traj, kept) is None

    def no_links(*_, **__):
        raise AssertionError("links checked where reach alone rules the view out")

    monkeypatch.setattr(flown_poses, "check_links", no_links)
    assert arm.flown_beyond(part, traj, len(traj)) is None
