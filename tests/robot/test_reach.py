"""`check_reach` follows a pass's branch a whole run at a time: the same joints as the
pose-by-pose rule (the in-limit solution nearest the previous joints), on paths with passes,
unreachable poses and branch changes."""

from __future__ import annotations

import numpy as np
import pytest

from scanplan.core.trajectory import Trajectory
from scanplan.robot.base import wrap
from scanplan.robot.flown_poses import HALF_TURN, flyable_poses
from scanplan.robot.nearest_joints import fit_limits, solvable
from scanplan.robot.presets import get_robot
from scanplan.robot.reach import _pass_start, _run_ends, check_reach, same_pass


def _pose_by_pose(poses, robot, q_start=None, swath=None, scanning=None, jump_deg=30.0):
    """The rule `check_reach` implements, one Python step a pose (its earlier form)."""
    arm = get_robot(robot)
    n = len(poses)
    linked = same_pass(n, swath, scanning)
    limits = arm.joint_limits
    solutions = arm.inverse(poses)
    exists = ~np.isnan(solutions).any(axis=2)
    tol = np.array([np.sin(np.radians(5.0)), np.sin(np.radians(5.0)), 20.0])
    joints = np.full((n, 6), np.nan)
    prev = None if q_start is None else np.asarray(q_start, dtype=float)
    entered = np.r_[True, ~linked]
    pinned = q_start is not None
    end = _run_ends(linked)
    for i in range(n):
        if not exists[i].any():
            continue
        if prev is not None and entered[i] and not pinned and end[i] == i + 1:
            # A move's pose: each branch turned the way nearest the joints before, if
            # within the limits, else as the IK gives it; the nearest within them.
            first, inside = fit_limits(solutions[i], limits)
            ok = inside & ~np.isnan(first).any(axis=1)
            if not ok.any():
                continue
            near, inside = fit_limits(prev + wrap(solutions[i] - prev), limits)
            first = np.where((inside & ~np.isnan(near).any(axis=1))[:, None], near, first)
            cand = first[ok]
            prev = cand[np.argmin(((cand - prev) ** 2).sum(axis=1))]
        elif prev is None or (entered[i] and not pinned):
            start = _pass_start(arm, solutions[i : end[i]], limits, prev, tol, jump_deg)
            if start is None:
                continue
            prev = start
        else:
            pinned = False
            cand = solutions[i][exists[i]]
            cand, inside = fit_limits(prev + wrap(cand - prev), limits)
            if not inside.any():
                continue
            cand = cand[inside]
            prev = cand[np.argmin(((cand - prev) ** 2).sum(axis=1))]
        joints[i] = prev
    return joints


def _path(robot: str, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smooth joint-space passes (some crossing the wrist singularity, some sweeping a joint
    past a limit), with moves between them and a few poses out of reach."""
    arm = get_robot(robot)
    rng = np.random.default_rng(seed)
    lim = np.clip(arm.joint_limits, -np.pi, np.pi)
    blocks, swath, scanning = [], [], []
    for k in range(12):
        q0 = rng.uniform(lim[:, 0] * 0.8, lim[:, 1] * 0.8)
        q1 = q0 + rng.normal(0, 0.6, 6)
        s = np.linspace(0, 1, int(rng.integers(20, 120)))[:, None]
        T = arm.forward(q0 + s * (q1 - q0))
        if k % 4 == 3:  # some poses out of reach
            T[len(T) // 3 : len(T) // 2, :3, 3] *= 5.0
        blocks.append(T)
        swath += [k] * len(T)
        scanning += [k % 5 != 4] * len(T)  # every fifth a move of its own poses
    return np.concatenate(blocks), np.array(swath), np.array(scanning)


@pytest.mark.parametrize("robot", ["ur5e", "kr6-r900"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_follows_the_pose_by_pose_rule(robot: str, seed: int) -> None:
    poses, swath, scanning = _path(robot, seed)
    q_start = get_robot(robot).inverse(poses[:1])[0, 0] if seed == 2 else None
    if q_start is not None and np.isnan(q_start).any():
        q_start = None
    got = check_reach(poses, robot, q_start, swath, scanning).joints
    want = _pose_by_pose(poses, robot, q_start, swath, scanning)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    assert np.isnan(got).any() and not np.isnan(got).all()  # both kinds of pose are met
    np.testing.assert_allclose(got, want, atol=1e-9, equal_nan=True)


@pytest.mark.parametrize("robot", ["ur5e", "kr6-r900"])
@pytest.mark.parametrize("pinned", [False, True])
def test_a_moves_poses_follow_the_pose_by_pose_rule_where_the_branch_changes(
    robot: str, pinned: bool
) -> None:
    # Moves (each pose flown alone) that wander smoothly, jump to far configurations (the
    # nearest branch changes: the stretch followed at once stops there), leave the reach,
    # and sweep the wrist past a turn (shifted into the limits), between short passes.
    arm = get_robot(robot)
    rng = np.random.default_rng(7)
    lim = np.clip(arm.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0] * 0.8, lim[:, 1] * 0.8)
    joints, swath, scanning = [], [], []
    for k in range(40):
        moving = k % 4 != 3
        for _ in range(int(rng.integers(3, 12))):
            if moving and rng.random() < 0.15:
                q = rng.uniform(lim[:, 0] * 0.8, lim[:, 1] * 0.8)
            else:
                q = q + rng.normal(0, 0.05, 6) + np.r_[0, 0, 0, 0, 0, 0.4 * moving]
            joints.append(q.copy())
            swath.append(k)
            scanning.append(not moving)
    poses = arm.forward(np.array(joints))
    poses[rng.random(len(poses)) < 0.05, :3, 3] *= 5.0  # out of reach
    swath, scanning = np.array(swath), np.array(scanning)
    q_start = np.array(joints[0]) if pinned else None
    got = check_reach(poses, robot, q_start, swath, scanning).joints
    want = _pose_by_pose(poses, robot, q_start, swath, scanning)
    np.testing.assert_allclose(got, want, atol=1e-9, equal_nan=True)
    moves = ~np.isnan(want).any(axis=1) & ~scanning
    signs = np.sign(arm.singularity_terms(want[moves]))
    assert (signs[1:] != signs[:-1]).any(axis=1).sum() >= 5  # branches changed in moves
    assert np.isnan(want[~scanning]).any()


@pytest.mark.parametrize("robot", ["ur5e", "kr6-r900"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_pose_has_joints_exactly_where_one_of_its_solutions_is_within_the_limits(
    robot: str, seed: int
) -> None:
    # Whichever branch the check follows: what `flyable_poses` asks without a cell, as
    # planned and turned about the beam, in one array operation (`solvable`).
    poses, swath, scanning = _path(robot, seed)
    arm = get_robot(robot)
    traj = Trajectory(poses, swath, scanning)
    flown = flyable_poses(traj, arm, np.eye(4), np.eye(4), None)
    for k, flange in enumerate((poses, poses @ HALF_TURN)):
        report = check_reach(flange, arm, swath=swath, scanning=scanning)
        has_joints = ~np.isnan(report.joints).any(axis=1)
        np.testing.assert_array_equal(solvable(arm.inverse(flange), arm.joint_limits), has_joints)
        np.testing.assert_array_equal(flown[k], has_joints)
    assert len(report.unreachable)
    assert len(report.limit_violations) or robot == "ur5e"  # a UR's joints turn ±360°


@pytest.mark.parametrize("stretch", [1, 7, 30, 200])
def test_follows_the_pose_by_pose_rule_across_stretches_beyond_the_limits(stretch: int) -> None:
    # One pass whose A3 folds beyond the KR 6's -120° limit for `stretch` poses, twice: the
    # poses there are skipped at once (growing windows), the same as stepped one by one.
    arm = get_robot("kr6-r900")
    q = np.tile(np.radians([20.0, -80.0, -100.0, 30.0, 40.0, 10.0]), (3 * stretch + 40, 1))
    q[:, 0] += np.linspace(0.0, 0.5, len(q))
    for lo in (10, 2 * stretch + 20):
        q[lo : lo + stretch, 2] = np.radians(-150.0)
    poses = arm.forward(q)
    swath, scanning = np.zeros(len(q), int), np.ones(len(q), bool)
    report = check_reach(poses, arm, swath=swath, scanning=scanning)
    want = _pose_by_pose(poses, "kr6-r900", swath=swath, scanning=scanning)
    np.testing.assert_allclose(report.joints, want, atol=1e-9, equal_nan=True)
    assert len(report.limit_violations) == 2 * stretch
    assert report.limit_violations[0] == 10 and report.limit_violations[-1] == 3 * stretch + 19


@pytest.mark.parametrize("stretch", [1, 7, 300])
def test_a_path_that_starts_beyond_the_limits_is_entered_where_it_comes_within(
    stretch: int,
) -> None:
    # Its first `stretch` poses fold A3 beyond the KR 6's limit, with no joints before them:
    # skipped at once to the first pose with an in-limit solution, the pass entered there.
    arm = get_robot("kr6-r900")
    q = np.tile(np.radians([20.0, -80.0, -100.0, 30.0, 40.0, 10.0]), (stretch + 40, 1))
    q[:, 0] += np.linspace(0.0, 0.5, len(q))
    q[:stretch, 2] = np.radians(-150.0)
    poses = arm.forward(q)
    swath, scanning = np.zeros(len(q), int), np.ones(len(q), bool)
    report = check_reach(poses, arm, swath=swath, scanning=scanning)
    want = _pose_by_pose(poses, "kr6-r900", swath=swath, scanning=scanning)
    np.testing.assert_allclose(report.joints, want, atol=1e-9, equal_nan=True)
    np.testing.assert_array_equal(report.limit_violations, np.arange(stretch))


class _Cell:
    """A cell as `check_reach` asks it (`pass_branches.CellView`): links clear wherever `along`
    says, joint moves clear except into the joints in `blocked_moves`."""

    def __init__(self, along=None, blocked_moves=()):
        self.along, self.blocked, self.moves = along, list(blocked_moves), []

    def clear_along(self, i, path):
        return np.ones(path.shape[:2], bool) if self.along is None else self.along(path)

    def clear_move(self, i0, q0, i1, q1):
        self.moves.append((i0, i1))
        return not any(np.allclose(q1, q, atol=1e-9) for q in self.blocked)


def _pass_after_a_move(robot: str = "ur5e"):
    """A move's pose, then a 60-pose pass that several branches fly whole."""
    arm = get_robot(robot)
    s = np.linspace(0, 1, 60)[:, None]
    q0 = np.array([0.3, -1.4, 1.6, -1.7, 0.9, 0.4])
    q1 = np.array([0.5, -1.2, 1.4, -1.5, 1.1, 0.2])
    poses = arm.forward(np.vstack([q0[None] - 0.3, q0 + s * (q1 - q0)]))
    return poses, np.r_[0, np.ones(60, int)], np.r_[False, np.ones(60, bool)]


def test_a_pass_is_entered_on_a_configuration_whose_links_are_clear() -> None:
    poses, swath, scanning = _pass_after_a_move()
    arm = get_robot("ur5e")
    free = check_reach(poses, arm, swath=swath, scanning=scanning)
    elbow = np.sign(arm.singularity_terms(free.joints[1:])[:, 1])
    assert (elbow == elbow[0]).all()
    # A cell where the elbow on the side the free choice took hits the table.
    cell = _Cell(along=lambda path: np.sign(arm.singularity_terms(path)[..., 1]) != elbow[0])
    report = check_reach(poses, arm, swath=swath, scanning=scanning, cell=cell)
    assert report.reachable and not np.isnan(report.joints).any()
    assert (np.sign(arm.singularity_terms(report.joints[1:])[:, 1]) == -elbow[0]).all()
    # What the cell chose is what a reader given the entries follows, without the cell.
    entries = {0: report.joints[0], 1: report.joints[1]}
    again = check_reach(poses, arm, swath=swath, scanning=scanning, entries=entries)
    np.testing.assert_allclose(again.joints, report.joints, atol=1e-9)


def test_a_pass_is_entered_where_the_joint_move_into_it_is_clear() -> None:
    poses, swath, scanning = _pass_after_a_move()
    arm = get_robot("ur5e")
    free = check_reach(poses, arm, swath=swath, scanning=scanning)
    # The move into the free choice's first pose sweeps a link into the cell.
    cell = _Cell(blocked_moves=[free.joints[1]])
    report = check_reach(poses, arm, swath=swath, scanning=scanning, cell=cell)
    assert cell.moves[0] == (0, 1)  # asked about the move from the pose before
    assert report.reachable and not np.isnan(report.joints[1:]).any()
    assert not np.allclose(report.joints[1], free.joints[1], atol=1e-6)
    # A cell that blocks every move in: the move is given up by the fit, not the pass here.
    everything = _Cell(along=None)
    everything.clear_move = lambda *args: False  # type: ignore[method-assign]
    blocked = check_reach(poses, arm, swath=swath, scanning=scanning, cell=everything)
    np.testing.assert_allclose(blocked.joints, free.joints, atol=1e-9)


def test_the_move_into_a_pass_is_flown_on_its_configuration_from_its_entry() -> None:
    # A pose of pass 0, a via point of the move into pass 1 (carrying its index), pass 1,
    # whose links are clear only on the elbow the free choice does not take.
    arm = get_robot("ur5e")
    s = np.linspace(0, 1, 60)[:, None]
    q0 = np.array([0.3, -1.4, 1.6, -1.7, 0.9, 0.4])
    q1 = np.array([0.5, -1.2, 1.4, -1.5, 1.1, 0.2])
    poses = arm.forward(np.vstack([q0[None] - 0.3, q0[None] - 0.15, q0 + s * (q1 - q0)]))
    swath = np.r_[0, 1, np.ones(60, int)]
    scanning = np.r_[True, False, np.ones(60, bool)]
    free = check_reach(poses, arm, swath=swath, scanning=scanning)
    elbow = np.sign(arm.singularity_terms(free.joints)[:, 1])
    assert elbow[0] == elbow[1] == elbow[2]

    class Pass1Cell(_Cell):  # pass 1's elbow (from pose 2 on) in the table
        def clear_along(self, i, path):
            hit = np.sign(arm.singularity_terms(path)[..., 1]) == elbow[2]
            return ~hit | (i + np.arange(len(path)) < 2)[:, None]

    cell = Pass1Cell()
    at_pass = check_reach(poses, arm, swath=swath, scanning=scanning, cell=cell)
    entry = np.r_[True, True, np.zeros(60, bool)]
    at_via = check_reach(poses, arm, swath=swath, scanning=scanning, cell=cell, entry=entry)
    for report in (at_pass, at_via):
        assert report.reachable
        assert (np.sign(arm.singularity_terms(report.joints[2:])[:, 1]) == -elbow[2]).all()
    # Entered at the pass: the via point is flown on the elbow of pass 0 and the arm turns
    # over beside the surface; entered at the via point, it turns over there.
    via = [np.sign(arm.singularity_terms(r.joints[1])[1]) for r in (at_pass, at_via)]
    assert via == [elbow[0], -elbow[2]]


def test_a_flip_on_the_linear_move_into_a_pass_stops_the_arm() -> None:
    # On the configuration it is entered with (as a plan records it), the move into pass 1
    # crosses the wrist singularity (q5 through 0), the pass itself does not: a controller
    # flies that move linearly and cannot change configuration in it.
    arm = get_robot("ur5e")
    lead = np.linspace(0, 1, 20)[:, None]
    q0 = np.array([0.3, -1.4, 1.6, -1.7, 0.35, 0.4])
    qm = np.array([0.4, -1.3, 1.5, -1.6, -0.35, 0.3])
    q1 = np.array([0.5, -1.2, 1.4, -1.5, -0.7, 0.2])
    run = np.linspace(0, 1, 40)[:, None]
    poses = arm.forward(np.vstack([q0 + lead * (qm - q0), qm + run[1:] * (q1 - qm)]))
    n = len(poses)
    swath = np.ones(n, int)
    scanning = np.r_[np.zeros(20, bool), np.ones(n - 20, bool)]
    at_top = np.r_[True, np.zeros(n - 1, bool)]
    flown = check_reach(poses, arm, swath=swath, scanning=scanning, entry=at_top, entries={0: q0})
    np.testing.assert_allclose(flown.joints[:20], (q0 + lead * (qm - q0)), atol=1e-8)
    assert len(flown.config_flips) == 1 and 1 <= flown.config_flips[0] < 20
    assert not flown.reachable
    assert "linear move" in flown.first_problem()[1]
    # Entered at the pass, the poses before it are moves of their own: nothing flips.
    at_pass = check_reach(poses, arm, swath=swath, scanning=scanning, entries={0: q0})
    assert len(at_pass.config_flips) == 0 and at_pass.reachable
