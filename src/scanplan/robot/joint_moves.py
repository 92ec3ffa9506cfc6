"""The sensor body along the joint moves a program makes (into a pass, at a reconfiguration,
after poses given up): the links are checked along them (`links.check_links`), but the
sensor swings with the wrist, and a wrist turning half a turn beside the surface sweeps it
through the part. `sensor_swept` finds such moves; `lift` finds where the arm can make one
clear of the cell instead: it moves up (or back along the beam) from where it is, makes
the joint move there, and moves straight down to the move's end.
"""

from __future__ import annotations

import numpy as np

from scanplan.robot.base import Robot
from scanplan.robot.export.thinning import linear_move
from scanplan.robot.links import LinkMemo, check_links, each_joint_move, joint_path
from scanplan.robot.nearest_joints import nearest_solution
from scanplan.robot.reach import JUMP_DEG
from scanplan.robot.straight_moves import LINE_STEP_MM, Way, fractions, not_flown
from scanplan.world.capsule_collision import CellObstacles

# How high a lift takes the sensor above a joint move's start and its end (mm; either may
# stay where it is), lowest first so that the extra way stays short: the sensor's body on a
# bracket sweeps a radius of a few hundred millimetres when the wrist turns. Last, both
# ends moved as far up and out from the base's axis (in where negative; mm): an arm folded
# close to its base has no reach up, and a base turning far sweeps less when stretched.
LIFT_HEIGHTS_MM = (0.0, 50.0, 100.0, 200.0, 300.0)
LIFT_OUT_MM = (100.0, 200.0, 300.0, -100.0, -200.0)
# The sensor body nearer the cell than this (mm) is in it (FCL's exact check below it): a
# joint move from or to a pose within the clearance must not bring it nearer, nor may
# any pose of a program (`flyable.check_flyable`).
TOUCH_MM = 1e-3


def sensor_swept(
    arm: Robot,
    joints: np.ndarray,
    entry: np.ndarray,
    T_part: np.ndarray,
    tcp: np.ndarray,
    obstacles: CellObstacles,
    clearance_mm: float | None = None,
) -> np.ndarray:
    """The poses i > 0 entered by a joint move (`entry` (n,)) from the last pose before with
    joints (`joints` (n, 6), NaN: none) along which the sensor body comes within
    `clearance_mm` of the cell (None: the obstacles' clearance), at the steps the links are
    checked at (`links.joint_path`); a move from or to a pose already that near, into it.
    T_part: the part's pose in the base frame, (4, 4) or one per pose (checked with the
    part at both ends of a move); tcp: `T_flange_sensor`."""
    T_all = np.asarray(T_part, dtype=np.float64)
    moves, ends, paths, parts = [], [], [], []
    for before, i, path in each_joint_move(joints, entry):
        for T in (T_all[before], T_all[i]) if T_all.ndim == 3 else (T_all,):
            moves.append(i)
            ends.append(joints[[before, i]])
            paths.append(path)
            parts.append(np.broadcast_to(np.linalg.inv(T), (len(path), 4, 4)))
    if not moves:
        return np.zeros(0, np.int64)
    sizes = [len(p) for p in paths]
    to_part = np.concatenate(parts)
    sensor = to_part @ arm.forward(np.concatenate(paths)) @ tcp
    at_ends = to_part[np.cumsum(sizes) - 1].repeat(2, axis=0) @ arm.forward(np.concatenate(ends))
    near = ~obstacles.sensor_clear(at_ends @ tcp, clearance_mm).reshape(-1, 2).all(axis=1)
    clear = obstacles.sensor_clear(sensor, clearance_mm)
    which = np.repeat(np.arange(len(moves)), sizes)
    if near.any():  # held to the cell itself
        inside = np.isin(which, np.flatnonzero(near))
        clear[inside] = obstacles.sensor_clear(sensor[inside], TOUCH_MM)
    return np.unique(np.array(moves)[np.unique(which[~clear])])


def _lift_offsets(T_part: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(k, 2, 3) how far each lift tried moves the sensor at a and at b (part frame), in the
    order tried: up by `LIFT_HEIGHTS_MM` (lowest first), back along the beam by the same,
    then up and out (`LIFT_OUT_MM`)."""
    up = T_part[2, :3]  # the base's vertical in the part's frame
    pairs = [(ha, hb) for ha in LIFT_HEIGHTS_MM for hb in LIFT_HEIGHTS_MM if ha or hb]
    pairs.sort(key=lambda p: (p[0] + p[1], max(p)))
    heights = np.array(pairs)[:, :, None]
    offsets = [heights * up, heights * -np.stack([a[:3, 2], b[:3, 2]])]
    axis = np.linalg.inv(T_part)[:3, 3]  # a point on the base's axis
    out = np.stack([p[:3, 3] - axis for p in (a, b)])
    out -= (out @ up)[:, None] * up
    out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-9)
    h, r = np.meshgrid(LIFT_HEIGHTS_MM, LIFT_OUT_MM, indexing="ij")
    offsets.append(h.reshape(-1, 1, 1) * up + r.reshape(-1, 1, 1) * out)
    return np.concatenate(offsets)


def lift(
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
    """How the arm can make the joint move from sensor pose a (joints q0) to b (q1) with the
    sensor body and the links clear of the cell: a joint move from a up (or back along its
    beam, or up and out; `_lift_offsets`) on q0's branch, one from there to a pose above b
    (the configuration nearest q1 there), a straight move down to b; the first whose joint
    moves keep the sensor body and the links clear at every step (the links by the reach
    check's own cautious check, `exact=False`, so that it enters those poses as found here)
    and whose straight move the arm flies (`straight_moves.not_flown`), those with no joint
    turning more than `reach.JUMP_DEG` from above b to b first. T_part (4, 4): the part's
    pose in the base frame. None if none does."""
    to_part, tcp = np.linalg.inv(T_part), np.linalg.inv(inv_tcp)
    offsets = _lift_offsets(T_part, a, b)
    moved = np.stack([a, b])[None].repeat(len(offsets), axis=0)
    moved[:, :, :3, 3] += offsets
    solutions = arm.inverse(T_part @ moved.reshape(-1, 4, 4) @ inv_tcp).reshape(
        len(offsets), 2, -1, 6
    )
    reached = []  # (order, ends, which ends move, joints there) of the lifts the arm reaches
    for k, ((start, end), (ha, hb), sol) in enumerate(
        zip(moved, np.linalg.norm(offsets, axis=2) > 0, solutions, strict=True)
    ):
        at_start = nearest_solution(sol[:1], arm.joint_limits, q0[None])
        at_end = nearest_solution(sol[1:], arm.joint_limits, q1[None])
        if at_start is not None and at_end is not None:
            # Last, a move down the reach check would not follow on its branch (a joint
            # turning more than `JUMP_DEG`): it may enter the pass above b on another, and
            # the fit then goes round that straight move again.
            jump = hb and np.degrees(np.abs(at_end[1] - q1)).max() > JUMP_DEG
            reached.append(
                (k + len(offsets) * jump, (start, end), (ha, hb), at_start[1], at_end[1])
            )
    for _, (start, end), (ha, hb), qa, qb in sorted(reached, key=lambda r: r[0]):
        path = np.concatenate([joint_path(q0, qa), qa[None], joint_path(qa, qb), qb[None]])
        if not obstacles.sensor_clear(to_part @ arm.forward(path) @ tcp).all():
            continue
        if check_links(arm, path, obstacles, T_part, exact=False, memo=memo).colliding.any():
            continue
        if hb and _not_straight(arm, T_part, inv_tcp, end, b, qb, obstacles, memo):
            continue
        # Up from a and across by joint moves, down to b by a straight one; an end not
        # moved stays where it is.
        vias = [p for p, moves in ((start, ha), (end, hb)) if moves]
        return Way(np.stack(vias), np.ones(len(vias), bool), not hb)
    return None


def _not_straight(
    arm: Robot,
    T_part: np.ndarray,
    inv_tcp: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    q0: np.ndarray,
    obstacles: CellObstacles,
    memo: LinkMemo | None,
) -> bool:
    """Whether the arm cannot fly the straight move from a to b from joints q0."""
    poses = linear_move(a, b, fractions(a, b, LINE_STEP_MM))
    lines = np.zeros(len(poses), np.int64)
    return bool(not_flown(arm, poses, T_part, inv_tcp, lines, {0: q0}, obstacles, memo).any())
