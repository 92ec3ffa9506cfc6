"""The sensor body along the joint moves a program makes: a wrist flipping beside the part
swings it through the part, which the fit lifts clear of and `export` refuses."""

from __future__ import annotations

import numpy as np
import trimesh

import scanplan.robot.fit as fit_module
from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.robot import get_robot
from scanplan.robot.export import parse_pose_arg
from scanplan.robot.fit_marks import FitMarks
from scanplan.robot.flyable import check_flyable
from scanplan.robot.joint_moves import TOUCH_MM, lift, sensor_swept
from scanplan.robot.links import check_links, joint_path, obstacles_for
from scanplan.robot.nearest_joints import fit_limits
from scanplan.robot.straight_moves import Way
from scanplan.world.cell import Cell
from scanplan.world.part import Part, part_from_mesh

TCP = parse_pose_arg("0,0,90,0,0,0")
T = parse_pose_arg("600,0,-100,0,0,0")  # the part 600 mm out in front of the arm
DOWN = np.diag([1.0, -1.0, -1.0])  # the beam (sensor z) pointing down


def _box() -> Part:
    """A 100 mm cube on the part's origin."""
    box = trimesh.creation.box((100.0, 100.0, 100.0))
    box.apply_translation((0.0, 0.0, 50.0))
    return part_from_mesh(box, "box")


def _over_box(z_mm: float) -> np.ndarray:
    """The sensor looking down at the box's middle from `z_mm` up (part frame)."""
    pose = np.eye(4)
    pose[:3, :3] = DOWN
    pose[:3, 3] = (0.0, 0.0, z_mm)
    return pose


def _wrists(arm, pose: np.ndarray) -> np.ndarray:
    """(2, 6) the arm's two in-limit wrist configurations at `pose` (elbow up)."""
    solutions = arm.inverse((T @ pose @ np.linalg.inv(TCP))[None])[0]
    joints, inside = fit_limits(solutions, arm.joint_limits)
    found = joints[inside & ~np.isnan(joints).any(axis=1)]
    elbow_up = found[found[:, 2] > 0]  # the KR 6's A3 > 0 here
    assert len(elbow_up) == 2 and np.sign(elbow_up[0, 4]) != np.sign(elbow_up[1, 4])
    return elbow_up


def test_a_wrist_flip_beside_the_part_swings_the_sensor_into_it_high_above_it_does_not() -> None:
    arm = get_robot("kr6-r900")
    spec = ScanSpec()
    obstacles = obstacles_for(_box(), Cell(), spec.sensor, spec.clearance_mm)
    entry = np.array([False, True])  # the second pose reached by a joint move
    near = _over_box(160.0)  # the emitter 60 mm over the top
    assert obstacles.sensor_clear(near[None]).all()
    flip = _wrists(arm, near)
    assert sensor_swept(arm, flip, entry, T, TCP, obstacles).tolist() == [1]
    assert sensor_swept(arm, flip, entry, T, TCP, obstacles, TOUCH_MM).tolist() == [1]
    # The links stay clear: only the sensor's own check finds it.
    assert not check_links(arm, flip, obstacles, T, entry).moves
    # The part's pose given per pose (a turntable standing still): the same answer.
    assert sensor_swept(arm, flip, entry, np.stack([T, T]), TCP, obstacles).tolist() == [1]
    # Not a joint move (a linear step): not judged here.
    assert sensor_swept(arm, flip, np.zeros(2, bool), T, TCP, obstacles).tolist() == []
    # The same flip 500 mm higher is clear.
    high = _over_box(600.0)
    solutions = arm.inverse((T @ high @ np.linalg.inv(TCP))[None])[0]
    joints, inside = fit_limits(solutions, arm.joint_limits)
    found = joints[inside & ~np.isnan(joints).any(axis=1)]
    for q in found[1:]:
        assert sensor_swept(arm, np.stack([found[0], q]), entry, T, TCP, obstacles).tolist() == []


def test_export_refuses_a_joint_move_that_swings_the_sensor_into_the_part() -> None:
    arm = get_robot("kr6-r900")
    spec = ScanSpec()
    part = _box()
    obstacles = obstacles_for(part, Cell(), spec.sensor, spec.clearance_mm)
    pose = _over_box(160.0)
    flip = _wrists(arm, pose)
    # Two passes at one pose, the second entered on the other wrist.
    two = Trajectory(np.stack([pose, pose]), np.array([0, 1]), np.array([True, True]))
    entries = {0: flip[0], 1: flip[1]}
    checked = check_flyable(two, arm, T, TCP, part, Cell(), spec.sensor, obstacles, entries=entries)
    assert not checked.flyable and checked.swept.tolist() == [1]
    assert "joint move that swings the sensor body into the part" in checked.first_problem(
        two.swath
    )
    assert checked.sensor_summary().endswith("swung into it by 1 joint moves")
    # Entered on the same wrist, nothing swings.
    same = {0: flip[0], 1: flip[0]}
    checked = check_flyable(two, arm, T, TCP, part, Cell(), spec.sensor, obstacles, entries=same)
    assert checked.flyable and "along every joint move" in checked.sensor_summary()


def test_a_lift_makes_the_flip_above_the_part_and_comes_straight_down() -> None:
    arm = get_robot("kr6-r900")
    spec = ScanSpec()
    obstacles = obstacles_for(_box(), Cell(), spec.sensor, spec.clearance_mm)
    pose = _over_box(160.0)
    q0, q1 = _wrists(arm, pose)
    inv = np.linalg.inv(TCP)
    way = lift(arm, T, inv, pose, pose, q0, q1, obstacles)
    assert way is not None
    # Up from the pose and across by joint moves, then a straight move down to it.
    assert way.jointed.all() and not way.end_jointed
    heights = way.poses[:, 2, 3]
    assert (heights > 160.0).all() and np.allclose(way.poses[:, :2, 3], 0.0)
    assert np.allclose(way.poses[:, :3, :3], DOWN)
    # Its joint moves keep the sensor clear: from q0 up, across to the wrist of q1.
    ups = arm.inverse(T @ way.poses @ inv)
    above = [
        ups[k][np.argmin(((fit_limits(ups[k], arm.joint_limits)[0] - q) ** 2).sum(axis=1))]
        for k, q in ((0, q0), (-1, q1))
    ]
    path = np.concatenate([joint_path(q0, above[0]), joint_path(above[0], above[-1])])
    assert obstacles.sensor_clear(np.linalg.inv(T) @ arm.forward(path) @ TCP).all()
    # Lifts are tried lowest first: where the wrist does not flip, 50 mm above the move's
    # end is already clear, joint-moved to and come straight down from.
    low = lift(arm, T, inv, pose, pose, q0, q0, obstacles)
    assert low is not None and len(low.poses) == 1 and not low.end_jointed
    assert np.isclose(low.poses[0, 2, 3], 160.0 + 50.0) and low.poses[0, 2, 3] < heights.max()


def test_ways_put_in_are_entered_as_they_say_and_the_pose_after_is_descended_to() -> None:
    poses = np.tile(np.eye(4), (4, 1, 1))
    poses[:, 0, 3] = np.arange(4.0)
    traj = Trajectory(poses, np.array([0, 0, 1, 1]), np.ones(4, bool))
    marks = FitMarks.of(traj)
    up = np.tile(np.eye(4), (2, 1, 1))
    up[:, 2, 3] = 100.0
    # Into pose 2 (pass 1's first): up and across by joint moves, straight down to it.
    lifted = Way(up, np.array([True, True]), False)
    grown_traj, grown = marks.with_ways(traj, {2: lifted})
    assert len(grown_traj) == 6 and grown_traj.swath.tolist() == [0, 0, 1, 1, 1, 1]
    assert grown_traj.scanning.tolist() == [True, True, False, False, True, True]
    assert grown.keep.all() and (grown.cause == -1).all()
    # The joint moves end at the poses put in; pass 1's first pose is not entered.
    assert np.flatnonzero(grown.entry(grown_traj)).tolist() == [0, 2, 3]
    assert grown.descended.tolist() == [False] * 4 + [True, False]
    # A detour's one pose, reached and left by joint moves.
    detour = Way(up[:1], np.array([True]), True)
    grown_traj, grown = marks.with_ways(traj, {3: detour})
    assert np.flatnonzero(grown.entry(grown_traj)).tolist() == [0, 2, 3, 4]


def test_a_straight_move_down_from_a_lift_the_arm_cannot_fly_is_made_a_joint_move() -> None:
    poses = np.tile(np.eye(4), (4, 1, 1))
    poses[:, 0, 3] = np.arange(4.0)
    traj = Trajectory(poses, np.array([0, 0, 1, 1]), np.ones(4, bool))
    up = np.tile(np.eye(4), (2, 1, 1))
    up[:, 2, 3] = 100.0
    lifted_traj, marks = FitMarks.of(traj).with_ways(traj, {2: Way(up, np.ones(2, bool), False)})
    assert not marks.entry(lifted_traj)[4]  # pass 1's first pose, reached straight down
    # The reach check found that straight move (into pose 4) not flyable: a joint move then.
    index = np.arange(len(lifted_traj))
    lines = np.array([4])
    _, marks, stuck = fit_module._gone_round(
        lifted_traj, lifted_traj, index, lines, np.zeros(0, int), np.zeros((6, 6)), marks,
        np.eye(4), get_robot("kr6-r900"), np.eye(4), None, {},
    )  # fmt: skip
    assert not len(stuck) and marks.entry(lifted_traj)[4]
