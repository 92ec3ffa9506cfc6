"""The straight moves a program flies between targets farther apart than a move's poses are
planned (`MOVE_STEP_MM`): where a fit gave up poses of a move and kept those either side,
the controller flies a straight line between the two that no pose of the plan lies on. This
checks that line as the controller flies it: the sensor's position moved linearly and its
orientation turned evenly, the arm staying on the branch it is on at the line's start. Where
the arm cannot fly it, `detour` finds a pose above it to pass through, by two straight moves
or two joint moves.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scanplan.core.trajectory import MOVE_STEP_MM, Trajectory
from scanplan.robot.base import Robot
from scanplan.robot.export.thinning import linear_move
from scanplan.robot.links import LinkMemo, check_links, joint_path
from scanplan.robot.nearest_joints import nearest_solution
from scanplan.robot.reach import check_reach
from scanplan.world.capsule_collision import CellObstacles

# The poses a straight line is checked at are this far apart at most: finer than the moves'
# own, as nothing else looks at the way between. Dense enough that the links' check, which
# lets a pose stand for those near it with its capsules grown by how far theirs moved
# (`links.LINK_STRIDE_MM`), bounds the whole way, not only the poses (at 5 mm two lines of
# the quadrotor's KR 6 plan passed that a check at 1 mm found a link within the clearance on).
LINE_STEP_MM = 1.0
# Where a detour's pose is looked for: above the middle of the straight move the arm cannot
# fly by these heights (mm, straight up in the cell), and moved these shares of the way
# towards the arm's base axis (where the line leaves its reach); nearest first, so that the
# joint moves there and on stay short.
DETOUR_HEIGHTS_MM = (100.0, 200.0, 300.0, 450.0, 600.0)
DETOUR_INWARD = (0.0, 0.25, 0.5)


@dataclass(frozen=True)
class Way:
    """Poses a program flies through before a pose of its plan: `poses` (k, 4, 4) sensor
    poses (part frame); `jointed` (k,) whether it reaches each by a joint move (else by a
    straight one); `end_jointed` whether it then reaches the pose itself by a joint move."""

    poses: np.ndarray
    jointed: np.ndarray
    end_jointed: bool


def long_steps(traj: Trajectory, entry: np.ndarray) -> np.ndarray:
    """Poses i (> 0) reached from pose i - 1 by a straight move longer than a move's poses
    are apart (not a joint move: `entry` (n,) marks those)."""
    length = np.linalg.norm(np.diff(traj.positions_mm, axis=0), axis=1)
    return 1 + np.flatnonzero((length > MOVE_STEP_MM * (1 + 1e-6)) & ~entry[1:])


def fractions(a: np.ndarray, b: np.ndarray, step_mm: float) -> np.ndarray:
    """(k,) how far along the line from pose a to pose b, both ends included, for poses at
    most `step_mm` apart."""
    length = float(np.linalg.norm(b[:3, 3] - a[:3, 3]))
    return np.linspace(0.0, 1.0, max(2, int(np.ceil(length / step_mm)) + 1))


def blocked_steps(
    arm: Robot,
    traj: Trajectory,
    T_part: np.ndarray,
    inv_tcp: np.ndarray,
    joints: np.ndarray,
    entry: np.ndarray,
    obstacles: CellObstacles | None = None,
    memo: LinkMemo | None = None,
    step_mm: float = LINE_STEP_MM,
) -> np.ndarray:
    """Of `long_steps(traj, entry)`, the poses i whose straight move in from pose i - 1 the
    arm cannot fly: on the way a pose out of reach or beyond the joint limits, a
    configuration flip or a joint turning fast, and in a cell (`obstacles`) a link within
    its clearance or the sensor body in it. `joints` (n, 6): the arm's along `traj` (NaN:
    none; such a step is not judged here). T_part: the part's pose in the base frame, (4, 4)
    or one per pose (a track's position moves linearly with the sensor). Each line is
    checked at poses `step_mm` apart at most."""
    steps = [int(i) for i in long_steps(traj, entry) if not np.isnan(joints[i - 1 : i + 1]).any()]
    if not steps:
        return np.zeros(0, np.int64)
    ends = [(traj.poses[i - 1], traj.poses[i]) for i in steps]
    t = [fractions(a, b, step_mm) for a, b in ends]
    sizes = np.array([len(f) for f in t])
    poses = np.concatenate([linear_move(a, b, f) for (a, b), f in zip(ends, t, strict=True)])
    T_all = np.asarray(T_part, dtype=np.float64)
    if T_all.ndim == 3:  # the part's pose along each line, moved with the sensor
        T_all = np.concatenate(
            [linear_move(T_all[i - 1], T_all[i], f) for i, f in zip(steps, t, strict=True)]
        )
    which = np.repeat(np.arange(len(steps)), sizes)
    first = np.r_[0, np.cumsum(sizes)[:-1]]
    starts = {int(f): joints[i - 1] for f, i in zip(first, steps, strict=True)}
    bad = not_flown(arm, poses, T_all, inv_tcp, which, starts, obstacles, memo)
    return np.array(steps, np.int64)[np.unique(which[bad])]


def not_flown(
    arm: Robot,
    poses: np.ndarray,
    T_part: np.ndarray,
    inv_tcp: np.ndarray,
    which: np.ndarray,
    starts: dict[int, np.ndarray],
    obstacles: CellObstacles | None,
    memo: LinkMemo | None,
) -> np.ndarray:
    """(n,) the sensor `poses` (part frame, the part at `T_part`) of straight lines (`which`
    line each is on) where the arm following each line from the joints `starts` gives at
    its first pose leaves its reach or limits, flips, turns a joint fast, or in a cell puts
    a link or the sensor body into it."""
    report = check_reach(
        T_part @ poses @ inv_tcp,
        arm,
        swath=which,
        scanning=np.ones(len(poses), bool),
        entries=starts,
    )
    bad = np.zeros(len(poses), bool)
    for found in (report.unreachable, report.limit_violations, report.config_flips):
        bad[found] = True
    bad[report.pass_jumps] = True
    if obstacles is not None:
        bad |= check_links(arm, report.joints, obstacles, T_part, memo=memo).colliding
        bad |= ~obstacles.sensor_clear(poses)
    return bad


def _detour_poses(T_part: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(k, 4, 4) the sensor poses a detour between poses a and b may pass through, in the
    order they are tried (`DETOUR_HEIGHTS_MM`, `DETOUR_INWARD`; part frame)."""
    up = T_part[2, :3]  # the base's vertical in the part's frame
    middle = linear_move(a, b, np.array([0.5]))[0]
    inward = np.linalg.inv(T_part)[:3, 3] - middle[:3, 3]  # to the base's origin
    inward -= (inward @ up) * up  # level: to its axis
    h, s = np.meshgrid(DETOUR_HEIGHTS_MM, DETOUR_INWARD, indexing="ij")
    out = np.repeat(middle[None], h.size, axis=0)
    out[:, :3, 3] += h.reshape(-1, 1) * up + s.reshape(-1, 1) * inward
    return out


def detour(
    arm: Robot,
    T_part: np.ndarray,
    inv_tcp: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    q0: np.ndarray,
    q1: np.ndarray,
    obstacles: CellObstacles,
    memo: LinkMemo | None = None,
) -> Way | None:
    """Where a program may go from sensor pose a (joints q0) to b (joints q1) when the arm
    cannot fly the straight line: through the first of `_detour_poses` (above the line's middle,
    T_part (4, 4) the part's pose in the base frame) the arm flies to and on from as it
    flies any straight line (`blocked_steps`), else by joint moves that keep the links and
    the sensor body clear of the cell at every step, the arm on the branch nearest q0
    there. None if none is."""
    above = _detour_poses(T_part, a, b)
    solutions = arm.inverse(T_part @ above @ inv_tcp)
    tcp, to_part = np.linalg.inv(inv_tcp), np.linalg.inv(T_part)
    for k, pose in enumerate(above):
        there, on = fractions(a, pose, LINE_STEP_MM), fractions(pose, b, LINE_STEP_MM)
        bent = np.concatenate([linear_move(a, pose, there), linear_move(pose, b, on[1:])])
        lines = np.zeros(len(bent), np.int64)
        if not not_flown(arm, bent, T_part, inv_tcp, lines, {0: q0}, obstacles, memo).any():
            return Way(pose[None], np.array([False]), False)
        found = nearest_solution(solutions[k : k + 1], arm.joint_limits, q0[None])
        if found is None:
            continue
        q = found[1]
        path = np.concatenate([joint_path(q0, q), q[None], joint_path(q, q1)])
        if not obstacles.sensor_clear(to_part @ arm.forward(path) @ tcp).all():
            continue
        if check_links(arm, path, obstacles, T_part, memo=memo).colliding.any():
            continue
        return Way(pose[None], np.array([True]), True)
    return None


def detours(
    traj: Trajectory,
    lines: np.ndarray,
    joints: np.ndarray,
    arm: Robot,
    T_part: np.ndarray,
    inv_tcp: np.ndarray,
    obstacles: CellObstacles,
    memo: LinkMemo | None = None,
) -> dict[int, Way]:
    """For the straight moves into poses `lines` of `traj` the arm cannot fly (`joints` the
    arm's along it), a `detour` each where there is one: {the line's end: the way there}."""
    found: dict[int, Way] = {}
    for i in lines:
        a, b = traj.poses[i - 1], traj.poses[i]
        way = detour(arm, T_part, inv_tcp, a, b, joints[i - 1], joints[i], obstacles, memo)
        if way is not None:
            found[int(i)] = way
    return found
