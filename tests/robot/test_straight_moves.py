"""The straight moves a program flies across poses a fit gave up are checked on the way, as
the controller flies them: a line the arm cannot follow is found, a short step is not judged."""

from __future__ import annotations

import numpy as np
import trimesh

from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import MOVE_STEP_MM, Trajectory
from scanplan.robot import check_reach, get_robot
from scanplan.robot.export import parse_pose_arg
from scanplan.robot.fit import fit_to_robot
from scanplan.robot.flyable import check_flyable
from scanplan.robot.links import obstacles_for
from scanplan.robot.straight_moves import blocked_steps, long_steps
from scanplan.world.capsule_collision import CellObstacles
from scanplan.world.cell import Cell
from scanplan.world.part import Part, part_from_mesh

TCP = parse_pose_arg("0,0,90,0,0,0")
DOWN = np.diag([1.0, -1.0, -1.0])  # the beam (sensor z) pointing down


def _moves(points) -> Trajectory:
    """Moves through `points` (part frame, mm), the sensor looking down: what is left of a
    move whose poses between were given up."""
    poses = np.tile(np.eye(4), (len(points), 1, 1))
    poses[:, :3, :3] = DOWN
    poses[:, :3, 3] = points
    return Trajectory(poses, np.zeros(len(points), np.int64), np.zeros(len(points), bool))


def _box(height_mm: float) -> Part:
    """A 100 mm square box `height_mm` tall on the part's origin."""
    box = trimesh.creation.box((100.0, 100.0, height_mm))
    box.apply_translation((0.0, 0.0, height_mm / 2))
    return part_from_mesh(box, "box")


def _box_cell(height_mm: float) -> CellObstacles:
    """`_box` in a cell, as the links and the sensor body see it."""
    spec = ScanSpec()
    return obstacles_for(_box(height_mm), Cell(), spec.sensor, spec.clearance_mm)


def _joints(arm, traj, T):
    """The arm's joints at each pose, each on the branch that reaches it."""
    flange = T @ traj.poses @ np.linalg.inv(TCP)
    return check_reach(flange, arm, swath=traj.swath, scanning=traj.scanning).joints


def test_only_straight_steps_longer_than_a_moves_spacing_are_long() -> None:
    x = [0.0, 10.0, 10.0 + MOVE_STEP_MM, 200.0, 400.0]
    traj = _moves([[v, 0.0, 300.0] for v in x])
    entry = np.zeros(len(x), bool)
    assert long_steps(traj, entry).tolist() == [3, 4]
    entry[3] = True  # reached by a joint move: not a straight one
    assert long_steps(traj, entry).tolist() == [4]


def test_a_straight_move_through_the_part_is_blocked_one_over_it_is_not() -> None:
    arm = get_robot("kr6-r900")
    obstacles = _box_cell(100.0)
    T = parse_pose_arg("600,0,-100,0,0,0")  # the part 600 mm out in front of the arm
    # Both ends are clear of the box beside it at 20 mm up; the line between runs through it.
    low = _moves([[-160.0, 0.0, 20.0], [160.0, 0.0, 20.0]])
    joints = _joints(arm, low, T)
    assert not np.isnan(joints).any()
    assert obstacles.sensor_clear(low.poses).all()
    entry = np.zeros(2, bool)
    inv = np.linalg.inv(TCP)
    assert blocked_steps(arm, low, T, inv, joints, entry, obstacles).tolist() == [1]
    # The part's pose given per pose (a track) and moved along: the same line, the same answer.
    assert blocked_steps(arm, low, np.stack([T, T]), inv, joints, entry, obstacles).tolist() == [1]
    # Without a cell only the arm's own limits count: it flies that line.
    assert blocked_steps(arm, low, T, inv, joints, entry).tolist() == []
    # High over the box the same line is clear.
    high = _moves([[-160.0, 0.0, 400.0], [160.0, 0.0, 400.0]])
    joints = _joints(arm, high, T)
    assert blocked_steps(arm, high, T, inv, joints, entry, obstacles).tolist() == []
    # Export's check of the arm refuses it, naming the line.
    checked = check_flyable(low, arm, T, TCP, _box(100.0), Cell(), ScanSpec().sensor, obstacles)
    assert not checked.flyable and checked.blocked_lines.tolist() == [1]
    assert "reached by a straight move from pose 0 the arm cannot fly" in checked.first_problem(
        low.swath
    )
    # A joint move instead is not a straight line: not judged here.
    assert blocked_steps(arm, low, T, inv, joints, np.ones(2, bool), obstacles).tolist() == []


def test_a_straight_move_that_takes_a_joint_past_its_limit_on_the_way_is_blocked() -> None:
    arm = get_robot("kr6-r900")
    T = np.eye(4)  # the part's origin at the arm's base
    # 300 mm out, looking down: 50 mm along y the wrist follows; across to the other side
    # of the x axis it turns past its limit on the way (the other side is flown on the
    # other wrist, which a straight move cannot change to).
    traj = _moves([[300.0, 200.0, 300.0], [300.0, 150.0, 300.0], [300.0, -200.0, 300.0]])
    joints = _joints(arm, traj, T)
    assert not np.isnan(joints).any()
    inv = np.linalg.inv(TCP)
    assert blocked_steps(arm, traj, T, inv, joints, np.zeros(3, bool)).tolist() == [2]


def test_a_fit_goes_round_a_straight_move_it_cannot_fly_by_a_pose_above_it() -> None:
    arm = get_robot("kr6-r900")
    obstacles = _box_cell(300.0)
    T = parse_pose_arg("600,0,-100,0,0,0")
    # A pose of pass 0 on one side of the box (far enough for the sensor's camera), the move
    # into pass 1 (up a little, over the box by a pose far out of the arm's reach, 2 m up,
    # and down), the pose of pass 1 on its other side: the fit gives the far pose up, and the
    # straight line left between the move's two low poses runs through the box.
    points = [[0.0, -450, 150], [0, -450, 170], [0, 0, 2000], [0, 450, 170], [0, 450, 150]]
    traj = _moves(points)
    traj = Trajectory(
        traj.poses, np.array([0, 1, 1, 1, 1]), np.array([True, False, False, False, True])
    )
    fit = fit_to_robot(traj, arm, TCP, T, obstacles=obstacles)
    assert fit.flyable and fit.blocked_lines == 0 and fit.moves_given_up == 1
    # Between the move's low poses a pose above the box, reached and left by joint moves,
    # on the joints the plan records.
    assert len(fit.traj) == 5
    assert 100.0 + 170.0 <= fit.traj.poses[2, 2, 3] <= 600.0 + 170.0
    assert fit.entry is not None and np.flatnonzero(fit.entry).tolist() == [0, 2, 3, 4]
    assert sorted(fit.record(TCP)["pass_entry_joints_deg"]) == ["0", "2", "3", "4"]
    # Without the detour the straight line is what the export check would refuse.
    line = _moves([points[1], points[3]])
    joints = _joints(arm, line, T)
    inv = np.linalg.inv(TCP)
    assert blocked_steps(arm, line, T, inv, joints, np.zeros(2, bool), obstacles).tolist() == [1]
